"""The fleet's inputs: the ``[fleet]`` settings, safe output names, one task per log.

:func:`discover` turns vessel folders, files and globs into :class:`LogTask` rows (one
log file of one vessel, hashed).  Hostile inputs (issue 15): an input that is not a
regular readable file (a FIFO, socket or device, a dangling link, an unreadable file, a
folder where ``--pattern`` names files) and, inside a vessel folder, a symbolic link
leading out of it, is a task with ``error`` set: listed as failed, never opened (a
FIFO's open blocks).  :func:`safe_name` and :func:`inside` keep vessel names from
escaping the output folder.
"""

from __future__ import annotations

import glob
import hashlib
import os
import unicodedata
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path, PurePath

from dracc.core.config import Config
from dracc.core.errors import ConfigError, FleetError, IngestError
from dracc.pipeline.audit.logs import file_sha256, input_problem, outside_link


@dataclass(frozen=True)
class FleetConfig:
    """The ``[fleet]`` table."""

    workers: int | None = None  #: local processes (default: the machine's CPU count)
    pattern: str = "**/*"  #: glob for log files inside a vessel folder (hidden files skipped)
    out: str | None = None  #: output folder (default "fleet-report")
    scheduler: str | None = None  #: Dask scheduler address, e.g. "tcp://10.0.0.5:8786"
    connect_timeout_s: float = 30.0  #: how long to wait for the Dask scheduler


def fleet_config(cfg: Config) -> FleetConfig:
    """Validate ``cfg.extra['fleet']`` into a :class:`FleetConfig`."""
    table = cfg.extra.get("fleet", {})
    if not isinstance(table, dict):
        raise ConfigError(f"[fleet] must be a table, got {type(table).__name__}")
    known = list(asdict(FleetConfig()))
    unknown = set(table) - set(known) - {"ranking"}  # [fleet.ranking]: fleet.ranking
    if unknown:
        raise ConfigError(
            f"[fleet] unknown key(s): {', '.join(sorted(unknown))}; "
            f"known: {', '.join(sorted(known))}"
        )
    kw: dict = {}
    if "workers" in table:
        w = table["workers"]
        if isinstance(w, bool) or not isinstance(w, int) or w < 1:
            raise ConfigError(f"[fleet] workers must be a positive integer, got {w!r}")
        kw["workers"] = w
    for key in ("pattern", "out", "scheduler"):
        if key in table:
            if not isinstance(table[key], str) or not table[key].strip():
                raise ConfigError(f"[fleet] {key} must be a non-empty string, got {table[key]!r}")
            kw[key] = table[key]
    if "connect_timeout_s" in table:
        v = table["connect_timeout_s"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise ConfigError(f"[fleet] connect_timeout_s must be a positive number, got {v!r}")
        kw["connect_timeout_s"] = float(v)
    return FleetConfig(**kw)


def check_scheduler(address: str | None, where: str, error: type[Exception]) -> None:
    """A Dask scheduler address must name a port (tcp://host:8786, host:8786): Dask says
    ValueError otherwise, deep inside the client.  Not checked without Dask (the batch then
    says what is missing)."""
    if not address:
        return
    try:
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.registry import get_backend
    except ImportError:
        return
    try:
        scheme, loc = parse_address(address)
        get_backend(scheme)  # an unknown scheme
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(loc)
    except ValueError as e:
        raise error(
            f"{where} {address!r}: {e}; expected an address such as tcp://host:8786"
        ) from None


# ------------------------------------------------------------------ names and paths


_UNSAFE = set('/\\:*?"<>|')
_RESERVED = (
    {"CON", "PRN", "AUX", "NUL"}
    | {f"COM{i}" for i in range(1, 10)}
    | {f"LPT{i}" for i in range(1, 10)}
)


def safe_name(name: str, max_len: int = 100) -> str:
    """A single path component for ``name``: separators and control characters become
    ``_``, leading/trailing dots and spaces go, Unicode letters stay (NFC).  When the
    result differs from ``name``, a short hash of ``name`` is appended so that two
    different names never share a folder."""
    nfc = unicodedata.normalize("NFC", name)
    s = "".join(
        "_" if (c in _UNSAFE or unicodedata.category(c).startswith("C")) else c for c in nfc
    )
    s = s.strip(" .")[:max_len]
    if not s or s.split(".")[0].upper() in _RESERVED:
        s = "_" + s
    if s != name:
        s = f"{s}-{hashlib.sha256(name.encode('utf-8', 'surrogatepass')).hexdigest()[:8]}"
    return s


def inside(root: Path, *parts: str) -> Path:
    """``root/part/...`` after :func:`safe_name` on each part, checked to stay inside ``root``."""
    base = root.resolve()
    p = base.joinpath(*(safe_name(x) for x in parts)).resolve()
    if p != base and base not in p.parents:
        raise FleetError(f"output path {p} would escape {base}")
    return p


# --------------------------------------------------------------------- the tasks


@dataclass(frozen=True)
class LogTask:
    """One log file of one vessel (or an input that cannot be read: ``error`` says why)."""

    vessel: str
    path: str  #: absolute
    log: str  #: as shown in tables: path relative to the vessel folder (or the file name)
    sha256: str | None  #: of the bytes; None for an input that cannot be read
    #: why the input cannot be read (a FIFO, socket or device, a dangling link, a folder
    #: where a file is expected, unreadable, a link out of its vessel folder); listed as
    #: failed without being opened or analysed
    error: str | None = None


_GLOB_CHARS = set("*?[")


def _expand(item: str) -> list[Path]:
    p = Path(item)
    if os.path.lexists(item):  # a dangling link too: listed as failed, not "no such file"
        return [p]
    if _GLOB_CHARS & set(item):
        return [Path(x) for x in sorted(glob.glob(item, recursive=True))]
    raise IngestError(f"{item}: no such file or folder")


def _names_files(pattern: str) -> bool:
    """True when the last part of ``pattern`` names files by their extension
    (``*.nmea``, ``2026-*.txt``): a folder it matches is a folder where a log was
    expected.  ``*`` and ``**`` match folders as well as files."""
    return "." in PurePath(pattern).name.strip("*")


def _task(vessel: str, path: Path, log: str) -> LogTask:
    """The task for one input: its hash, or why it cannot be read (never blocking:
    :func:`dracc.pipeline.audit.input_problem` opens nothing but a regular file)."""
    absolute = os.path.abspath(path)
    problem = input_problem(path)
    if problem is None:
        try:
            return LogTask(vessel, str(Path(path).resolve()), log, file_sha256(path))
        except IngestError as err:
            return LogTask(vessel, absolute, log, None, str(err))
    return LogTask(vessel, absolute, log, None, f"{path}: {problem}")


def discover(inputs: Iterable[str | Path], pattern: str = "**/*") -> list[LogTask]:
    """The tasks for ``inputs``: a folder is one vessel (its name), holding log files
    matching ``pattern``; a file (or a glob's files) belongs to the vessel named by its
    parent folder.  Hidden files and folders are skipped; a file listed twice counts once.

    An input that is not a regular readable file is a task with ``error`` set (listed as
    failed, never opened): a FIFO, socket or device, a dangling link, an unreadable file,
    a folder matching a pattern that names files (``*.nmea``), and, inside a vessel
    folder, a symbolic link whose target lies outside that folder (not followed)."""
    tasks: dict[str, LogTask] = {}

    def add(t: LogTask) -> None:
        tasks.setdefault(t.path, t)

    for item in inputs:
        matches = _expand(str(item))
        if not matches:
            raise IngestError(f"{item}: the pattern matches nothing")
        for m in matches:
            if m.is_dir():
                vessel = m.resolve().name
                for f in sorted(m.glob(pattern)):
                    rel = f.relative_to(m)
                    if any(x.startswith(".") for x in rel.parts):
                        continue
                    target = outside_link(f, m)
                    if target is not None:
                        add(
                            LogTask(
                                vessel,
                                os.path.abspath(f),
                                rel.as_posix(),
                                None,
                                f"{f}: symbolic link to {target}, outside the vessel folder "
                                f"{m}: not followed",
                            )
                        )
                    elif f.is_dir():
                        if _names_files(pattern):
                            add(
                                LogTask(
                                    vessel,
                                    os.path.abspath(f),
                                    rel.as_posix(),
                                    None,
                                    f"{f}: is a directory, not a log file",
                                )
                            )
                    else:
                        add(_task(vessel, f, rel.as_posix()))
            else:  # a file, or something in a file's place (FIFO, device, dangling link)
                parent = m.resolve().parent if m.exists() else Path(os.path.abspath(m)).parent
                add(_task(parent.name, m, m.name))
    if not tasks:
        raise IngestError("no log files found in the inputs")
    return sorted(tasks.values(), key=lambda t: (t.vessel, t.log, t.path))
