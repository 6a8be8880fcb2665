"""Option types and checks every command shares, so that an option means one thing everywhere.

A value given on the command line that dracc cannot use is a usage error (exit 2, README
"Exit codes"): typer's own checks, the checks below (OptionError), or the validation of the
configuration the options were merged into (a ConfigError, see :func:`option_values`).
"""

from __future__ import annotations

import datetime as dt
import functools
import re
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path, PurePath
from typing import Annotated, Any

import typer

from dracc.core.config import Config, load_config, validate
from dracc.core.durations import parse_duration_s, parse_reset_s
from dracc.core.errors import ConfigError, OptionError
from dracc.core.vocabulary import ROLES

_LOGS_HELP = (
    "Log files (NMEA text, CSV or MCAP; gzip, xz, bzip2 or zstd compressed too; '-' for"
    " standard input); several files of one voyage merge by time."
)
_CONFIG_HELP = "TOML configuration file (see README)."

LogFiles = Annotated[list[Path], typer.Argument(help=_LOGS_HELP)]
ConfigFile = Annotated[Path | None, typer.Option("--config", "-c", help=_CONFIG_HELP)]

#: ``--json PATH``: the command's JSON document to PATH (atomic), or ``-`` for stdout
#: (written by :func:`dracc.report.output.emit_json`).
JsonOut = Annotated[
    str | None,
    typer.Option(
        "--json",
        metavar="PATH|-",
        help="Write the JSON document to PATH, or '-' for stdout.",
    ),
]

#: ``--html PATH``: one self-contained offline HTML page
HtmlOut = Annotated[
    Path | None,
    typer.Option("--html", metavar="PATH", help="Write one self-contained offline HTML page."),
]

#: ``analyze``'s exports for the tools navigators run (dracc.report.exports, mcap_export)
GpxOut = Annotated[
    Path | None,
    typer.Option(
        "--gpx",
        metavar="PATH",
        help="Write GPX 1.1 (OpenCPN, chart plotters): water track, DR over the ground, fix-"
        "updated EP, reference; a segment per leg, the 2M per point, waypoints at the misses.",
    ),
]
KmlOut = Annotated[
    Path | None,
    typer.Option(
        "--kml",
        metavar="PATH",
        help="Write KML 2.2 (Google Earth, with its time slider): the tracks and the 2M "
        "circles at the reporting epochs.",
    ),
]
GeoJsonOut = Annotated[
    Path | None,
    typer.Option(
        "--geojson",
        metavar="PATH",
        help="Write GeoJSON (RFC 7946): the tracks, and a polygon per 2M circle and "
        "error ellipse at the reporting epochs with time, radius and inside.",
    ),
]
McapOut = Annotated[
    Path | None,
    typer.Option(
        "--mcap",
        metavar="PATH",
        help="Write an MCAP for Foxglove: the inputs' positions and headings, the DR over the "
        "ground and fix-updated EP with their covariance, the 2M as GeoJSON (layout: docs/).",
    ),
]

#: ``--role KEY=ROLE`` (repeatable), read by :func:`parse_roles`
Roles = Annotated[
    list[str] | None,
    typer.Option(
        "--role",
        help="Map a source to a role, KEY=ROLE (repeatable), "
        "e.g. --role INS2=ins2 --role II=compass.",
    ),
]
Strict = Annotated[bool, typer.Option("--strict", help="Fail on the first rejected line.")]
IgnoreChecksum = Annotated[
    bool,
    typer.Option("--ignore-checksum", help="Accept lines with wrong checksums (still counted)."),
]
LogDate = Annotated[
    str | None, typer.Option("--date", help="UTC date YYYY-MM-DD for logs that carry none.")
]

#: the same two as defaults, for commands that declare ``config: Path | None = ConfigOption``
ConfigOption = typer.Option(None, "--config", "-c", exists=False, help=_CONFIG_HELP)
LogsArgument = typer.Argument(..., help=_LOGS_HELP)


@contextmanager
def option_values() -> Iterator[None]:
    """Read the command-line option values inside this block: a :class:`ConfigError`
    raised here names a bad option value and becomes an :class:`OptionError` (exit 2).
    Load the configuration file before the block (its errors stay exit 4)."""
    try:
        yield
    except ConfigError as e:
        raise OptionError(str(e)) from e


def options_only(command: Callable[..., Any]) -> Callable[..., Any]:
    """Decorator for a command that reads no configuration file (``simulate``): every
    :class:`ConfigError` it raises comes from its options, a usage error (exit 2)."""

    @functools.wraps(command)
    def run(*args: Any, **kwargs: Any) -> Any:
        with option_values():
            return command(*args, **kwargs)

    return run


def parse_roles(items: list[str]) -> dict[str, str]:
    """['INS2=ins2', 'II=compass'] -> {'INS2': 'ins2', 'II': 'compass'}."""
    roles: dict[str, str] = {}
    for item in items:
        key, sep, role = item.partition("=")
        key, role = key.strip(), role.strip().lower()
        if not sep or not key:
            raise ConfigError(f"--role {item!r}: expected KEY=ROLE, e.g. --role INS2=ins2")
        if role not in ROLES:
            raise ConfigError(f"--role {item!r}: role must be one of {', '.join(ROLES)}")
        roles[key] = role
    return roles


def check_choice(
    value: str | None, known: Iterable[str], option: str, none_known: str = "nothing to choose from"
) -> str | None:
    """``value`` if it is one of ``known`` (or None); else an OptionError listing them
    (``none_known`` says why the list is empty)."""
    known = list(known)
    if value is None or value in known:
        return value
    if not known:
        raise OptionError(f"{option} {value!r}: {none_known}")
    raise OptionError(f"{option} {value!r}: expected one of {', '.join(known)}")


def check_date(value: str | None, option: str = "--date") -> str | None:
    """A calendar date ``YYYY-MM-DD`` (or None); else an OptionError."""
    if value is None:
        return None
    try:
        if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", value.strip()):
            raise ValueError
        return dt.date.fromisoformat(value.strip()).isoformat()
    except ValueError:
        raise OptionError(f"{option} {value!r}: expected a date YYYY-MM-DD") from None


def check_pattern(value: str | None, option: str = "--pattern") -> str | None:
    """A relative glob for the files inside a folder (``*.nmea``, ``**/*.nmea``) or None."""
    if value is None:
        return None
    if not value.strip() or PurePath(value).is_absolute() or PurePath(value).drive:
        raise OptionError(
            f"{option} {value!r}: expected a glob relative to the folder, "
            "e.g. '*.nmea' or '**/*.nmea'"
        )
    return value


def build_config(
    config: Path | None,
    *,
    interval: str | None = None,
    window: str | None = None,
    dr_reset: str | None = None,
    probability: float | None = None,
    roles: list[str] | None = None,
    date: str | None = None,
    strict: bool = False,
    ignore_checksum: bool = False,
    epoch_interval: str | None = None,
    variation_deg: float | None = None,
    fix_role: str | None = None,
) -> Config:
    """The configuration file with the options on top: how analyze, audit and records
    take it (one validation path: a file one accepts the others accept).  An error of the
    file is a ConfigError (exit 4); a bad option value, or one the validated file's
    settings cannot take, an OptionError (exit 2)."""
    cfg = load_config(config)  # validated: what fails below comes from the options
    with option_values():
        ing = cfg.ingest
        sources = {**ing.sources, **parse_roles(roles or [])}
        date = check_date(date)
        ing = replace(
            ing,
            sources=sources,
            strict=ing.strict or strict,
            ignore_checksum=ing.ignore_checksum or ignore_checksum,
            date=date if date is not None else ing.date,
        )
        dev = cfg.deviation
        if interval is not None:
            dev = replace(dev, interval_s=parse_duration_s(interval, "--interval"))
        if window is not None:
            dev = replace(dev, window_s=parse_duration_s(window, "--window"))
        if probability is not None:
            if not 0.5 <= probability < 1.0:
                raise ConfigError(f"--probability {probability}: must be in [0.5, 1)")
            dev = replace(dev, probability=probability)
        dr = cfg.dead_reckoning
        if dr_reset is not None:
            try:
                if dr_reset.strip().lower() != "auto":
                    parse_reset_s(dr_reset)
            except ConfigError as e:
                raise ConfigError(
                    f"--dr-reset {dr_reset!r}: expected auto, 1h, 4h, 30min, watch or never"
                ) from e
            dr = replace(dr, reset=dr_reset)
        if epoch_interval is not None:
            dr = replace(dr, epoch_interval_s=parse_duration_s(epoch_interval, "--epoch-interval"))
        if variation_deg is not None:
            if not -180.0 <= variation_deg <= 180.0:
                raise ConfigError(
                    f"--variation {variation_deg}: must be within ±180 degrees (east +)"
                )
            dr = replace(dr, variation_deg=variation_deg)
        if fix_role is not None:
            if fix_role not in ("gnss", "ins_mean"):
                raise ConfigError(f"--fix-role {fix_role!r}: must be gnss or ins_mean")
            dr = replace(dr, fix_role=fix_role)
        return validate(replace(cfg, ingest=ing, deviation=dev, dead_reckoning=dr))
