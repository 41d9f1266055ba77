"""Names that become parts of file names (`check_name`, `safe_name`) and the one way an output
path is built (`out_path`, `written_whole`, `claim_out`; docs/design_core.md, "Output paths")."""

from __future__ import annotations

import contextlib
import os
import re
import uuid
from pathlib import Path, PurePosixPath, PureWindowsPath

MAX_NAME = 64
NAME_RULE = (
    f"a name of ASCII letters, digits, '_', '-' and '.', not starting with '.', at most "
    f"{MAX_NAME} characters"
)
_NAME = re.compile(rf"[A-Za-z0-9_-][A-Za-z0-9_.-]{{0,{MAX_NAME - 1}}}")


def is_name(value) -> bool:
    return isinstance(value, str) and _NAME.fullmatch(value) is not None


def check_name(value, where: str) -> str:
    """`value` if it is a name (see the module docstring); ValueError naming `where` (file and
    field) and the value (quoted, cut to 80 characters) otherwise."""
    if is_name(value):
        return value
    shown = repr(value) if not isinstance(value, str) else repr(value[:80])
    raise ValueError(f"{where} must be {NAME_RULE}, got {shown}")


def safe_name(text: str, fallback: str = "run") -> str:
    """A name made of `text` (a user's file or folder name): every other character replaced by
    '_', leading dots dropped, cut to MAX_NAME characters; `fallback` if nothing is left."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", str(text)).lstrip(".")[:MAX_NAME]
    return name if is_name(name) else fallback


def out_path(out, *parts: str) -> Path:
    """`out / parts...`, a path to write: ValueError unless every part is relative without a
    '..' (or NUL) and the result, symbolic links resolved, lies inside `out`."""
    out = Path(out)
    for part in parts:
        part = str(part)
        pure = PurePosixPath(part.replace("\\", "/"))
        if (
            not part
            or "\0" in part
            or pure.is_absolute()
            or PureWindowsPath(part).is_absolute()
            or ".." in pure.parts
        ):
            raise ValueError(f"{out}: output name {part!r} would leave the output folder")
    path = out.joinpath(*parts)
    base = out.resolve()
    try:
        target = path.resolve()
    except (OSError, RuntimeError) as exc:  # a symbolic-link loop
        raise ValueError(f"{path}: cannot be written ({exc})") from None
    if target != base and not target.is_relative_to(base):
        raise ValueError(
            f"{path}: resolves to {target}, outside the output folder {out} (a symbolic link?)"
        )
    return path


_MADE: list = []  # folders `claim_out` made and holds now


def release_claims() -> None:
    """Remove the held folders `claim_out` made that are still empty (for a process ending
    without unwinding, e.g. `os._exit` on a signal)."""
    for out in _MADE:
        with contextlib.suppress(OSError):
            out.rmdir()


@contextlib.contextmanager
def claim_out(out):
    """Create `out` if needed and hold it for this process while the block runs: ValueError
    naming it if another process holds it (an advisory `flock` on the folder, released when
    the block ends or the process dies; where the platform has no `fcntl`, no lock). A folder
    this call created and nothing was written into is removed again."""
    out = Path(out)
    created = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    try:
        import fcntl
    except ImportError:  # not POSIX
        fcntl = None
    fd = os.open(out, os.O_RDONLY) if fcntl is not None else None
    try:
        if fd is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise ValueError(
                    f"--out {out}: another graphloc process is writing there (wait for it to "
                    "end, or choose another --out)"
                ) from None
        if created:
            _MADE.append(out)
        yield out
    finally:
        if created and out in _MADE:
            _MADE.remove(out)
        if fd is not None:
            os.close(fd)
        if created:
            with contextlib.suppress(OSError):  # not empty, or gone: left as it is
                out.rmdir()


@contextlib.contextmanager
def written_whole(path):
    """Yield a temporary path beside `path` (hidden, same suffix: writers that pick a format by
    suffix still do) for the caller to write; rename it over `path` when the block ends
    without an error (an atomic replace), remove it otherwise."""
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:12]}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
