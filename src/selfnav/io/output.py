"""Writing outputs safely: the one helper every writer of the package goes through.

* **Atomic**: a file is written to a temporary file beside it and moved into place; a set of
  files (``simulate``, ``evaluate --report``, ``demo``) is written to a temporary folder and
  moved in while Ctrl-C is held back, so an interrupt leaves the old set or the new set, never
  a mix, and no temporary file behind.
* **Through symlinks**: ``--out link`` replaces the file the link points to; the link stays.
* **Never over special files**: a device, pipe or socket named as an output is refused in one
  line (``--out /dev/null`` as root would otherwise replace the device node).
* **Modes**: new files get ``0666 & ~umask`` (0644 under the usual 022), folders
  ``0777 & ~umask``; a replaced file keeps its mode.
* **Parents**: missing parent folders are created; a file in the way, a folder named as a
  file or an unwritable place is one line (:class:`~selfnav.errors.OutputError`, exit 2).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import stat
import tempfile
import threading
from pathlib import Path

from selfnav.errors import OutputError


def umask() -> int:
    """The process umask (read without changing it where Linux allows)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    old = os.umask(0o022)
    os.umask(old)
    return old


def _real(path: Path) -> Path:
    """``path`` with a symlink at its end followed (the link itself is kept)."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _first_existing(folder: Path) -> Path:
    p = folder
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    return p


def check_folder_writable(folder, shown=None) -> None:
    """Refuse, in one line, a folder that cannot be created or written into (without creating
    anything): a file in the way, no permission."""
    folder = Path(folder)
    shown = shown if shown is not None else folder
    anc = _first_existing(folder)
    if anc.exists() and not anc.is_dir():
        raise OutputError(shown, f"{anc} is a file, not a folder")
    if not anc.exists():  # a dangling symlink on the way
        raise OutputError(shown, f"{anc} is a broken link")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise OutputError(shown, f"cannot write in {anc} (permission denied)")


def check_output_file(path, suffixes=()) -> Path:
    """Check an output file path before any work is done; return the file that will be
    replaced (the target of a symlink). Nothing is created. ``suffixes``: the allowed
    extensions (e.g. ``(".png",)``), any when empty."""
    shown = Path(path)
    if str(path) in ("", "-"):
        raise OutputError(shown or "-", "give a file name (selfnav writes files, not stdout)")
    if isinstance(path, str) and (path.endswith(("/", os.sep)) or shown.name in ("", ".", "..")):
        raise OutputError(path, "names a folder (it ends in '/'): give a file name (e.g. "
                          f"{shown / 'solution.csv'})")
    if suffixes and shown.suffix.lower() not in suffixes:
        raise OutputError(shown, f"give a name ending in {' or '.join(suffixes)} (the file "
                          f"written is {suffixes[0].lstrip('.').upper()})")
    target = _real(shown)
    if target.exists():
        st = os.stat(target)
        if stat.S_ISDIR(st.st_mode):
            raise OutputError(shown, "is a folder: give a file name (e.g. "
                              f"{shown / 'solution.csv'})")
        if not stat.S_ISREG(st.st_mode):
            raise OutputError(shown, "is a special file (device, pipe or socket): selfnav "
                              "writes regular files only and will not replace it")
        if not os.access(target, os.W_OK) and not os.access(target.parent, os.W_OK):
            raise OutputError(shown, "cannot be replaced (permission denied)")
    elif os.path.lexists(target):
        raise OutputError(shown, "is a broken link")
    check_folder_writable(target.parent, shown)
    return target


def check_output_folder(path) -> Path:
    """Check an output folder path before any work is done; return the folder to write into
    (the target of a symlink). Nothing is created."""
    shown = Path(path)
    target = _real(shown)
    if target.exists():
        if not target.is_dir():
            raise OutputError(shown, "is a file, not a folder: give a folder name")
        if not os.access(target, os.W_OK | os.X_OK):
            raise OutputError(shown, "cannot write in this folder (permission denied)")
    else:
        check_folder_writable(target.parent, shown)
    return target


def _make_parents(folder: Path, shown) -> None:
    check_folder_writable(folder, shown)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(shown, f"cannot create the folder {folder} ({e.strerror})") from None


def _new_mode(target: Path, folder: bool = False) -> int:
    if not folder and target.exists():
        return stat.S_IMODE(os.stat(target).st_mode)
    return (0o777 if folder else 0o666) & ~umask()


@contextlib.contextmanager
def uninterrupted():
    """Hold Ctrl-C back for the duration of the block (a few renames), then deliver it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: got.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)
        if got and callable(old):
            old(signal.SIGINT, None)  # the handler in force (KeyboardInterrupt by default)
        elif got and old == signal.SIG_DFL:
            raise KeyboardInterrupt


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; move it into place only if the block succeeds.

    Nothing half-written is ever left at ``path`` (nor the temporary file, on failure). The
    checks and modes of the module docstring apply; an ``OSError`` while writing (disk full)
    becomes one line naming ``path``.
    """
    shown = Path(path)
    target = check_output_file(shown)
    _make_parents(target.parent, shown)
    mode = _new_mode(target)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as e:
        raise OutputError(shown, f"cannot create a file in {target.parent} ({e.strerror})") \
            from None
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, mode)
        os.replace(tmp, target)
    except OSError as e:
        _unlink(tmp)
        raise OutputError(shown, f"cannot be written ({e.strerror or e})") from None
    except BaseException:
        _unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_paths(*paths):
    """Yield temporary paths beside each of ``paths``; on success move them all into place
    while Ctrl-C is held back (a file and its JSON sidecar: the new pair or the old, never a
    mix). The checks of :func:`atomic_path` apply to each."""
    with contextlib.ExitStack() as stack:
        tmps = [stack.enter_context(_deferred(p)) for p in paths]
        yield [t for t, _ in tmps]
        with uninterrupted():
            for tmp, commit in tmps:
                commit()


@contextlib.contextmanager
def _deferred(path):
    """:func:`atomic_path` whose final move is done by the caller (``commit``)."""
    shown = Path(path)
    target = check_output_file(shown)
    _make_parents(target.parent, shown)
    mode = _new_mode(target)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as e:
        raise OutputError(shown, f"cannot create a file in {target.parent} ({e.strerror})") \
            from None
    os.close(fd)

    def commit():
        try:
            os.chmod(tmp, mode)
            os.replace(tmp, target)
        except OSError as e:
            raise OutputError(shown, f"cannot be written ({e.strerror or e})") from None

    try:
        yield tmp, commit
    finally:
        _unlink(tmp)     # gone already when committed


def _unlink(p) -> None:
    with contextlib.suppress(OSError):
        os.unlink(p)


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write bytes to ``path`` through a temporary file moved into place."""
    check_output_file(path)           # a str ending in '/' names a folder: refused
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(data)
    return Path(path)


def atomic_write_text(path, text: str) -> Path:
    """Write UTF-8 text to ``path`` through a temporary file moved into place."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_copy(src, path) -> Path:
    """Copy the file ``src`` to ``path`` through a temporary file moved into place."""
    with atomic_path(path) as tmp:
        shutil.copyfile(src, tmp)
    return Path(path)


@contextlib.contextmanager
def atomic_folder(path, owned=()):
    """Yield a temporary folder; on success its files replace those in the folder ``path``.

    Parameters
    ----------
    path : folder to write (created with its parents when missing; a symlink is followed)
    owned : names of the files this kind of output may contain: those not written this time
        are removed from ``path`` so that no file of an older set stays beside the new set.
        Other files in the folder are left alone.

    A missing folder appears whole (a renamed temporary sibling); an existing one gets its
    files replaced by renames while Ctrl-C is held back. On any failure the temporary folder is
    removed and ``path`` is as it was.
    """
    shown = Path(path)
    target = check_output_folder(shown)
    fresh = not target.exists()
    if fresh:
        _make_parents(target.parent, shown)
        base = target.parent
    else:
        base = target
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.selfnav-", dir=base))
    except OSError as e:
        raise OutputError(shown, f"cannot be written ({e.strerror})") from None
    try:
        yield tmp
        with uninterrupted():
            if fresh and not os.path.lexists(target):
                os.chmod(tmp, _new_mode(target, folder=True))
                os.rename(tmp, target)
                return
            written = set(os.listdir(tmp))
            for name in written:
                os.replace(tmp / name, target / name)
            for name in set(owned) - written:
                p = target / name
                if p.is_file() or p.is_symlink():
                    _unlink(p)
            os.rmdir(tmp)
    except OSError as e:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OutputError(shown, f"cannot be written ({e.strerror or e})") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise




def figure_png(fig, dpi: int = 110, **kw) -> bytes:
    """A matplotlib figure as PNG bytes (nothing written)."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, **kw)
    return buf.getvalue()


def write_figure(fig, path, dpi: int = 110, **kw) -> Path:
    """Write a matplotlib figure as PNG to ``path`` (must end in ``.png``), atomically."""
    check_output_file(path, (".png",))
    return atomic_write_bytes(path, figure_png(fig, dpi, **kw))


__all__ = ["atomic_path", "atomic_paths", "atomic_write_bytes", "atomic_write_text", "atomic_copy",
           "atomic_folder", "check_output_file", "check_output_folder", "uninterrupted", "umask",
           "figure_png", "write_figure"]
