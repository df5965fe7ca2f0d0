"""``selfnav montecarlo``: seeded Monte Carlo of a (scenario, method) pair on Dask."""
from __future__ import annotations

from typing import Annotated, List, Optional

import typer

from selfnav.cli import options as opt
from selfnav.cli.common import emit_json
from selfnav.errors import SelfnavError


def _parse_sets(items) -> dict:
    out = {}
    for s in items or ():
        if "=" not in s:
            raise SelfnavError(f"--set expects KEY=VALUE, got '{s}'")
        k, v = s.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def register(app: typer.Typer) -> None:
    @app.command("montecarlo")
    def montecarlo_cmd(
        scenario: Optional[str] = typer.Argument(None, metavar="SCENARIO", help="Registered scenario (see --list), "
                                                 "e.g. static-latitude."),
        runs: opt.at_least(1, "--runs", help="Number of seeded runs.") = 100,
        workers: opt.Workers = 2,
        scheduler: opt.Scheduler = None,
        out: opt.out_file("Per-run results, .csv or .parquet.", required=False) = None,
        seed: Annotated[int, typer.Option("--seed", min=0, help="Master seed, ≥ 0 (run i gets "
                                          "SeedSequence(seed, spawn_key=(i,))).")] = 0,
        sets: Optional[List[str]] = typer.Option(None, "--set", help="Scenario parameter "
                                                 "KEY=VALUE (repeatable; see --list)."),
        chunk_size: opt.at_least(1, "--chunk-size", help="Runs per Dask task.",
                                 optional=True) = None,
        as_json: opt.Json = False,
        list_: bool = typer.Option(False, "--list", help="List the scenarios and parameters."),
    ):
        """Error statistics of a method over N seeded simulations against its own sigma."""
        from selfnav import api
        from selfnav import campaigns  # noqa: F401  (registers the pairs that run the API)
        from selfnav import montecarlo as mc
        from selfnav.io.output import check_output_file

        if list_:
            info = {p.name: {"unit": p.unit, "description": p.description,
                             "defaults": p.defaults} for p in mc.REGISTRY.values()}
            if as_json:
                emit_json(info)
            else:
                for name, d in info.items():
                    print(f"{name}: {d['description']} (error in {d['unit']})")
                    for k, v in d["defaults"].items():
                        print(f"    --set {k}={v}")
            return
        if not scenario:
            raise SelfnavError("give a scenario (see selfnav montecarlo --list)")
        if runs < 1:
            raise SelfnavError(f"--runs must be at least 1 (got {runs})")
        if workers < 0:
            raise SelfnavError(f"--workers must be 0 (in-process) or more (got {workers})")
        if out is not None:
            check_output_file(out, (".csv", ".parquet", ".pq"))
        pair = mc.get_pair(scenario)
        params = mc.resolve_params(pair, _parse_sets(sets))
        kw = dict(seed=seed, params=params, workers=workers, scheduler=scheduler,
                  chunk_size=chunk_size, out=out)
        if as_json:
            res = api.run_montecarlo(scenario, runs, **kw)
        else:
            from rich.console import Console
            from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                                       TimeElapsedColumn, TimeRemainingColumn)

            with Progress(TextColumn("[progress.description]{task.description}"), BarColumn(),
                          MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
                          console=Console(stderr=True), transient=False) as bar:
                task = bar.add_task(f"{scenario}", total=runs)
                res = api.run_montecarlo(scenario, runs, **kw,
                                         progress=lambda k: bar.advance(task, k))
        d = res.to_dict()
        if out is not None:
            d["out"] = str(out)
        if as_json:
            emit_json(d)
            return
        u = res.unit
        s = res.summary
        print(f"{scenario}: {s['n']} runs, seed {seed}, {res.scheduler} "
              f"({res.workers} workers), {res.elapsed_s:.1f} s")
        print(f"  RMS error            {s['rms_error']:.4g} {u}   (mean {s['mean_error']:+.3g})")
        print(f"  RMS predicted sigma  {s['rms_sigma']:.4g} {u}")
        print(f"  RMS(error/sigma)     {s['rms_normalized_error']:.3f}   (1 = consistent)")
        print(f"  within 2 sigma       {100 * s['fraction_within_2sigma']:.1f} % ± "
              f"{100 * s['fraction_within_2sigma_se']:.1f} %   (95.4 % for Gaussian errors)")
        if "rms_bound" in s:
            print(f"  RMS bound            {s['rms_bound']:.4g} {u}   error/bound "
                  f"{s['rms_error_over_bound']:.3f}")
        if out is not None:
            print(f"  results: {d['out']}")
