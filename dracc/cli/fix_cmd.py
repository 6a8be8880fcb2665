"""``dracc fix``: fuse position fixes and lines of position at the chart table.

Options -> :func:`dracc.pipeline.fix.run_fix` (the observations read in the navigator's
units, :mod:`dracc.ingest.observations`, and fused by LS (W1) / WLS (W4),
:mod:`dracc.math.fix`) -> the tables
(:func:`dracc.report.fix_report.render`) or the ``dracc.fix/1`` JSON (docs/fix.md).

Exit codes: 0 a fix; 2 a bad option value (the message names the option and the
value); 3 the geometry cannot give a (unique) fix, or the observation file is missing;
4 the observation file (TOML) is invalid (the message names the file, table and key).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from dracc.cli.app import app, err, out
from dracc.cli.options import JsonOut
from dracc.ingest.observations import (
    DEFAULT_ABEAM_SIGMA_M,
    DEFAULT_BEARING_SIGMA_DEG,
    DEFAULT_FIX_SIGMA_M,
    DEFAULT_LINE_SIGMA_M,
    DEFAULT_PIER_SIGMA_M,
)
from dracc.pipeline.fix import run_fix_free_gyro
from dracc.report.fix_report import render, to_json
from dracc.report.output import STDOUT, emit_json
from dracc.report.write import writing

_OBS_HELP = "Repeatable. Coordinates: 54.6, -18.8, '54 36.5N', '018 48.2E', \"54°36.5'N\"."


def _repeated(option: str, metavar: str, help_text: str) -> Any:
    return typer.Option([], option, metavar=metavar, help=help_text)


@app.command("fix")
def fix_cmd(
    fix: list[str] = _repeated(
        "--fix",
        "LAT,LON[,SIGMA_M]",
        f"A position fix (default sigma {DEFAULT_FIX_SIGMA_M:g} m). {_OBS_HELP}",
    ),
    range_: list[str] = _repeated(
        "--range",
        "LAT,LON,DIST[,SIGMA]",
        "Range of a mark, DIST with a unit: 2.4nmi, 2.4nm, 4cbl, 450m, "
        "1.2km; SIGMA the same (bare: metres; default: IMO radar, "
        "max(30 m, 1 % of DIST) / 2).",
    ),
    bearing: list[str] = _repeated(
        "--bearing",
        "LAT,LON,BRG_DEG[,SIGMA_DEG]",
        f"True bearing of the mark taken from the ship (default sigma {DEFAULT_BEARING_SIGMA_DEG:g}°).",
    ),
    bearing_mark: list[str] = _repeated(
        "--bearing-from-mark",
        "LAT,LON,BRG_DEG[,SIGMA_DEG]",
        "True bearing of the ship taken at the mark (D/F, VOR).",
    ),
    line: list[str] = _repeated(
        "--line",
        "LAT1,LON1,LAT2,LON2[,SIGMA_M[,OFFSET_M]]",
        "Straight line of position A->B (a transit); OFFSET_M > 0: "
        f"the ship is right of A->B (default sigma {DEFAULT_LINE_SIGMA_M:g} m).",
    ),
    pier: list[str] = _repeated(
        "--pier",
        "LAT1,LON1,LAT2,LON2,HEADING_DEG,port|starboard,"
        "HALF_BREADTH_M[,SIGMA_M[,GAP_M[,REF_STBD_M]]]",
        "Lying alongside the pier line A->B, SIDE to the pier (default "
        f"sigma {DEFAULT_PIER_SIGMA_M:g} m; GAP_M fenders; REF_STBD_M the "
        "reference point to starboard of the centreline).",
    ),
    abeam: list[str] = _repeated(
        "--abeam",
        "LAT,LON[,SIGMA_M]",
        "A pier mark abeam of the reference point (needs one --pier; "
        f"default sigma {DEFAULT_ABEAM_SIGMA_M:g} m).",
    ),
    nadir: list[str] = _repeated(
        "--nadir",
        "SUBLAT,SUBLON,NADIR_DEG[,SIGMA_DEG]",
        "Free-gyro nadir circle about the sub-point (default sigma 1'; needs --prior when alone).",
    ),
    gyro_vector: list[str] = _repeated(
        "--gyro-vector",
        "UX,UY,UZ,TIME_S,NADIR_DEG[,SIGMA_DEG[,SIGMA_U_DEG[,SIGMA_T_S]]]",
        "Free-gyro spin-axis unit vector (inertial frame), time and nadir angle (Jeong's "
        "free-gyro paper (1)); sigmas of the nadir angle (default 1'), the vector and the clock; the "
        "report adds the paper's error model and FDOP (docs/free-gyro.md).",
    ),
    prior: str | None = typer.Option(
        None,
        "--prior",
        metavar="LAT,LON",
        help="Linearisation point, e.g. the DR position (default: the mean "
        "of the fixes, else of the marks; then other solutions are "
        "searched for and an ambiguity is an error).",
    ),
    file: Path | None = typer.Option(
        None,
        "--file",
        "-f",
        metavar="OBS.TOML",
        help="Observations as TOML table arrays named fix, range, bearing, "
        "line, pier, abeam, nadir, gyro_vector, and an optional prior table "
        "(docs/fix.md); they combine with the options.",
    ),
    ls: bool = typer.Option(
        False, "--ls", help="Unweighted least squares (W1) instead of WLS (W4)."
    ),
    datum: str | None = typer.Option(
        None,
        "--datum",
        metavar="NAME",
        help="Datum of the options' charted positions (ED50, NAD27, OSGB36, Tokyo, "
        "'Pulkovo 1942', EPSG:4230 ...), brought to WGS-84 before fusion (default WGS84).",
    ),
    json_out: JsonOut = None,
) -> None:
    """Fuse position fixes and lines of position (LS/WLS): position, error ellipse, DOP, residuals.

    Exit codes: 0 a fix; 2 a bad option value; 3 no (unique) fix from this geometry, or
    --file missing; 4 an invalid --file.
    """
    options = [
        ("--fix", fix),
        ("--range", range_),
        ("--bearing", bearing),
        ("--bearing-from-mark", bearing_mark),
        ("--line", line),
        ("--pier", pier),
        ("--abeam", abeam),
        ("--nadir", nadir),
        ("--gyro-vector", gyro_vector),
    ]
    rep, datums, gyro = run_fix_free_gyro(options, file, prior, weighted=not ls, datum=datum)
    if json_out != STDOUT:
        render(rep, out, datums, gyro)
    if json_out is None:
        return
    with writing(json_out):
        written = emit_json(to_json(rep, datums, gyro), json_out)
    if written:
        err.print(f"wrote {written}", highlight=False, markup=False)
