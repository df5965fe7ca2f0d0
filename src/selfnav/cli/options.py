"""Options shared by the commands, defined once: the same name, help and choices everywhere.

Each is an ``Annotated`` type (or a factory of one where the help names what the command
writes). Choices are real choices: ``--help`` lists them and a bad value is a one-line usage
error. Flags are positive (``--smooth``, ``--window-test/--no-window-test``).

The choice lists are spelled here (the command line must start without importing numpy and
scipy); ``tests/test_cli_options.py`` checks that they equal the library's
(:data:`selfnav.io.readers.IMU_FORMATS`, :data:`selfnav.datum.DATUMS`,
:data:`selfnav.sensors.GRADE_NAMES`, ...).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated, Callable, Optional

import typer
import typer.core

IMU_FORMATS = ("auto", "csv", "psins", "psins-csv", "psins-mat", "rtklibexplorer", "kfgins",
               "ulog")
GNSS_FORMATS = ("auto", "csv", "pos", "nmea", "psins-avp", "ulog")
#: :data:`selfnav.axes.PRESETS` (``tests/test_cli_options.py`` checks they are the same)
AXES_PRESETS = ("rtklibexplorer-drive0708", "px4", "kfgins", "ros")
DATUMS = ("wgs84", "pz90.11", "pz90", "sk42")
GRADES = ("navigation", "tactical", "industrial", "consumer")
SIM_GRADES = (*GRADES, "perfect")
NAV_GRADES = ("auto", *GRADES)
#: selfnav.ins.config.PLATFORM_NAMES (a test keeps them equal; the CLI does not import the filter)
PLATFORMS = ("auto", "car", "pedestrian", "rover", "boat", "aircraft", "drone", "ship", "walker",
             "multirotor")
RAW_FORMATS = ("auto", "rinex", "ubx", "android", "smartloc", "psins")


def checked_choice(choices, normalize: Callable[[str], str] | None = None):
    """A typer callback accepting one of ``choices`` (case-insensitive; ``normalize`` maps
    aliases onto a choice or raises) and returning it as a plain ``str``."""

    def check(value):
        if value is None:
            return None
        key = str(value).strip().lower()
        if normalize is not None:
            try:
                key = normalize(key)
            except Exception:
                key = None
        if key not in choices:
            raise typer.BadParameter(f"'{value}' is not one of {', '.join(choices)}")
        return key

    return check


def choice_option(*decls, choices, help: str, normalize=None, hidden: bool = False):
    """``typer.Option`` of a choice: ``--help`` shows ``[a|b|c]``, a bad value is one line."""
    return typer.Option(*decls, metavar="[" + "|".join(choices) + "]", help=help, hidden=hidden,
                        callback=checked_choice(choices, normalize))


def datum_key_lazy(name: str) -> str:
    from selfnav.datum import datum_key  # lazily: only the commands that take a datum pay

    return datum_key(name)


# ---------------------------------------------------------------- inputs
ImuFile = Annotated[Path, typer.Option(
    "--imu", help="IMU file: native CSV (t, wx, wy, wz, fx, fy, fz; s, rad/s, m/s²), PSINS "
                  ".imu, rtklibexplorer CSV with its .tag, KF-GINS, PX4 ULog .ulg (see "
                  "--imu-format).")]
OptionalImuFile = Annotated[Optional[Path], typer.Option(
    "--imu", help="IMU file: native CSV (t, wx, wy, wz, fx, fy, fz; s, rad/s, m/s²), PSINS "
                  ".imu, rtklibexplorer CSV with its .tag, KF-GINS, PX4 ULog .ulg (see "
                  "--imu-format); not with --gnss-raw.")]
ImuArgument = Annotated[Path, typer.Argument(
    help="IMU record (native CSV, PSINS .imu, ...; see --imu-format).")]
GnssFile = Annotated[Path, typer.Option(
    "--gnss", help="GNSS fixes: native CSV (t, lat_deg, lon_deg, h_m[, sigma_m]), RTKLIB .pos "
                   "or NMEA (see --gnss-format).")]
OptionalGnssFile = Annotated[Optional[Path], typer.Option(
    "--gnss", help="GNSS fixes: native CSV (t, lat_deg, lon_deg, h_m[, sigma_m, ve, vn, vu]), "
                   "RTKLIB .pos, NMEA or a PSINS avp CSV (see --gnss-format); optional with "
                   "--init.")]
MapFile = Annotated[Optional[Path], typer.Option(
    "--map", help="Road map: OpenStreetMap .osm or .osm.pbf.")]
ImuFormat = Annotated[str, choice_option(
    "--imu-format", choices=IMU_FORMATS,
    help="Format of the IMU file; auto: by name (.imu PSINS, .ulg PX4 ULog, a .tag beside it "
         "rtklibexplorer, else CSV). rtklibexplorer applies upstream's -0.125 s time offset.")]
#: the old spelling of ``--imu-format`` (hidden; still accepted)
ImuFormatOld = Annotated[Optional[str], choice_option(
    "--format", choices=IMU_FORMATS, help="Same as --imu-format.", hidden=True)]


def check_axes(value):
    if value is None:
        return None
    from selfnav.axes import AxesError, imu_frame

    try:
        imu_frame(value)
    except AxesError as e:
        raise typer.BadParameter(str(e)) from None
    return value.strip()


def check_mount(value):
    if value is None:
        return None
    from selfnav.axes import AxesError, parse_mount

    try:
        return parse_mount(value)
    except AxesError as e:
        raise typer.BadParameter(str(e)) from None


ImuAxes = Annotated[Optional[str], typer.Option(
    "--imu-axes", metavar="AXES", callback=check_axes,
    help="What the IMU file's x, y, z point to: three letters of R L F B U D (right, left, "
         "forward, back, up, down; NED reads as FRD), e.g. FRD, RFU, FLU, or x=-F,y=R,z=U; a "
         "preset (" + ", ".join(AXES_PRESETS) + "); or detect (navigate finds them from gravity "
         "and the GNSS accelerations before it runs, imu_axes in --json; up alone: the sideways "
         "constraint off). Default: the format's documented axes (docs/readers.md).")]
ImuMount = Annotated[Optional[str], typer.Option(
    "--imu-mount", metavar="R,P,Y", callback=check_mount,
    help="Roll, pitch, yaw of the IMU on the vehicle, deg (DESIGN §2 conventions: yaw "
         "clockwise from above, pitch nose-up, roll right side down), applied after "
         "--imu-axes; overrides a preset's.")]
GnssFormat = Annotated[str, choice_option(
    "--gnss-format", choices=GNSS_FORMATS,
    help="Format of the GNSS file; auto: by extension (.pos RTKLIB, .nmea/.nma/.gga NMEA, "
         ".ulg PX4 ULog, else CSV).")]
GnssDatum = Annotated[str, choice_option(
    "--gnss-datum", choices=DATUMS, normalize=datum_key_lazy,
    help="Datum of the GNSS file's coordinates (converted to WGS-84 on reading).")]
OutDatum = Annotated[str, choice_option(
    "--out-datum", choices=DATUMS, normalize=datum_key_lazy,
    help="Datum of the coordinates written.")]
Grade = Annotated[str, choice_option(
    "--grade", choices=GRADES, help="IMU grade: its noise model (selfnav.sensors.GRADES).")]
NavGrade = Annotated[str, choice_option(
    "--grade", choices=NAV_GRADES,
    help="IMU noise prior: auto (measured from the data, the consumer preset where nothing is "
         "still) or a grade of selfnav.sensors.GRADES; where the data is noisier than a preset, "
         "the measured noise wins and a warning says so.")]
SimGrade = Annotated[Optional[str], choice_option(
    "--grade", choices=SIM_GRADES,
    help="IMU grade of the simulated sensors (perfect: no errors); default the scenario's.")]

# ---------------------------------------------------------------- outputs
Json = Annotated[bool, typer.Option(
    "--json", help="Print one JSON object on stdout (nothing else there; notes go to stderr).")]


def file_path(value) -> Path:
    """An output FILE name as typed: one ending in ``/`` names a folder and is refused in one
    line (``Path`` would drop the slash and write a file named like the folder)."""
    if isinstance(value, Path):
        return value
    text = str(value)
    if text.endswith(("/", os.sep)) or Path(text).name in ("", ".", ".."):
        base = text.rstrip("/" + os.sep) or "."
        raise typer.BadParameter(f"'{text}' names a folder (it ends in '/'): give a file name, "
                                 f"e.g. {base}/solution.csv")
    return Path(text)


def out_file(what: str, required: bool = True):
    """``--out FILE``: the help says what the file holds and how it is written."""
    return Annotated[Path if required else Optional[Path], typer.Option(
        "--out", parser=file_path, metavar="FILE",
        help=f"{what} A FILE, written atomically (through a symlink, never over a "
             "device); missing parent folders are created.")]


def out_folder(what: str):
    """``--out DIR``: the help says what goes in the folder."""
    return Annotated[Path, typer.Option(
        "--out", help=f"{what} A FOLDER (created with its parents); the set of files is "
                      "replaced whole, other files in it are left alone.")]


# ---------------------------------------------------------------- numbers with a range
def _in_range(what: str, lo: float, hi: float):
    def check(value):
        if value is not None and not lo <= value <= hi:
            raise typer.BadParameter(f"{value:g} is not a {what} in degrees ({lo:g}..{hi:g})")
        return value

    return check


#: Callbacks for options that take a latitude / longitude in degrees.
check_latitude_deg = _in_range("latitude", -90.0, 90.0)
check_longitude_deg = _in_range("longitude", -180.0, 360.0)


def latitude_deg(*decls, help: str):
    """A latitude in degrees: -90 to 90."""
    return Annotated[float, typer.Option(*decls, callback=check_latitude_deg, help=help)]


def longitude_deg(*decls, help: str):
    """A longitude in degrees: -180 to 360."""
    return Annotated[float, typer.Option(*decls, callback=check_longitude_deg, help=help)]


def positive(*decls, help: str, optional: bool = False):
    """A number that must be > 0 (σ, a length, a duration): a bad value is one line."""
    return Annotated[Optional[float] if optional else float, typer.Option(
        *decls, callback=_positive, help=help)]


def _positive(value):
    if value is not None and not value > 0:
        raise typer.BadParameter(f"must be positive (got {value:g})")
    return value


def at_least(minimum: int, *decls, help: str, optional: bool = False):
    """An integer that must be at least ``minimum``: a bad value is one line."""
    def check(value):
        if value is not None and value < minimum:
            raise typer.BadParameter(f"must be at least {minimum} (got {value})")
        return value

    return Annotated[Optional[int] if optional else int, typer.Option(
        *decls, callback=check, help=help)]


# ---------------------------------------------------------------- Dask
Workers = at_least(0, "--workers", help="Local Dask workers (processes, one thread each); 0: "
                                        "in this process without Dask.")
Scheduler = Annotated[Optional[str], typer.Option(
    "--scheduler", metavar="ADDRESS", help="Address of an existing Dask scheduler (tcp://host:8786); "
                        "--workers is then ignored.")]
Seed = Annotated[int, typer.Option("--seed", min=0, help="Random seed (≥ 0): the same seed "
                                                         "gives the same result.")]


# ---------------------------------------------------------------- --help panels
#: The panels each command's ``--help`` groups its options into, by parameter name, in order
#: (an option's own ``rich_help_panel`` wins; one found in no panel goes under "Other
#: options", which tests/test_cli_options.py refuses, so that a new option gets a panel).
HELP_PANELS = {
    "navigate": {
        "Inputs": ("imu", "gnss", "gnss_raw", "map_", "init", "odometer", "mag", "imu_format",
                   "gnss_format", "gnss_datum", "imu_axes", "imu_mount"),
        "Outputs": ("out", "out_rate", "out_datum", "fix_log", "as_json"),
        "Method": ("method", "smooth", "grade", "drift_guard"),
        "Sensor geometry and timing (estimated when not given)": (
            "lever_arm", "imu_time_offset", "nhc_lever", "mount_states", "scale_factors"),
        "Vehicle constraints": ("platform", "nhc", "magnetometer_aid"),
        "--method seed only": ("matcher", "ins_datum", "declination_deg"),
    },
    "moving": {
        "Inputs": ("imu", "attitude", "imu_format", "imu_rates", "lat0_deg", "lon0_deg",
                   "imu_axes", "imu_mount"),
        "Outputs": ("out", "out_step_s", "json_out"),
        "Method": ("method", "observer", "gain", "bandwidth_hz", "grade", "drift_deg_h",
                   "attitude_time_offset"),
    },
    "latitude": {
        "Inputs": ("imu", "imu_format", "h_m", "imu_axes", "imu_mount"),
        "Method": ("method", "rest"),
        "Outputs": ("as_json",),
        "Error budget (--budget)": ("budget", "gyro_bias_deg_h", "accel_bias_ug"),
        "Sensor requirements (--requirements)": ("requirements", "lat_deg", "seed_constants"),
    },
    "match": {
        "Inputs": ("gnss", "map_path", "gnss_datum"),
        "Outputs": ("out", "route_out", "out_datum", "as_json"),
        "Matcher": ("sigma_m", "radius_m", "beta_m"),
        "Dask": ("workers", "scheduler"),
    },
    "montecarlo": {
        "Campaign": ("scenario", "runs", "seed", "sets", "list_"),
        "Outputs": ("out", "as_json"),
        "Dask": ("workers", "scheduler", "chunk_size"),
    },
    "simulate": {"Scenario": ("scenario", "seed", "grade", "duration", "dt", "start"),
                 "Outputs": ("out", "as_json", "imu_axes", "imu_mount")},
    "evaluate": {"Inputs": ("truth", "solution", "map_path"), "Outputs": ("report", "as_json")},
    "allan": {"Inputs": ("imu", "imu_format", "imu_axes", "imu_mount"),
              "Outputs": ("plot", "as_json")},
    "attitude": {"Inputs": ("imu", "imu_format", "imu_axes", "imu_mount", "gnss", "reference"),
                 "Method": ("grade", "declination_deg", "lat_deg", "lon_deg", "no_mag", "step"),
                 "Outputs": ("out", "as_json")},
    "spp": {"Inputs": ("gnss_raw", "nav", "fmt"),
            "Method": ("elevation_mask_deg", "smoothing_s", "systems", "fde"),
            "Outputs": ("out", "sat_log", "receiver_out", "as_json")},
    "demo": {"Outputs": ("out", "as_json")},
}
OTHER_PANEL = "Other options"


def help_panel(command: str, param) -> str:
    """The ``--help`` panel of a parameter of ``command`` (:data:`HELP_PANELS`)."""
    own = getattr(param, "rich_help_panel", None)
    if own:
        return own
    for panel, names in HELP_PANELS.get(command, {}).items():
        if param.name in names:
            return panel
    return OTHER_PANEL


class GroupedCommand(typer.core.TyperCommand):
    """A command whose plain ``--help`` lists its options in panels (:data:`HELP_PANELS`),
    the way typer's rich help would with ``rich_help_panel``, without rich's markup."""

    def format_options(self, ctx, formatter) -> None:
        args, panels = [], {}
        order = list(HELP_PANELS.get(self.name, {}))
        for param in self.get_params(ctx):
            rv = param.get_help_record(ctx)
            if rv is None:
                continue
            if param.param_type_name == "argument":
                args.append(rv)
            else:
                name = "Options" if param.name == "help" else help_panel(self.name, param)
                panels.setdefault(name, []).append(rv)
        if args:
            with formatter.section("Arguments"):
                formatter.write_dl(args)
        for name in [*order, OTHER_PANEL, "Options"]:
            if panels.get(name):
                with formatter.section(name):
                    formatter.write_dl(panels[name])
