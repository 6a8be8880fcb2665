"""``dracc fix`` as one library call: the observations as the navigator gives them
(options and an observation file, :mod:`dracc.ingest.observations`) fused into a fix
(:mod:`dracc.math.fix`: LS (W1) or WLS (W4)).  Gyro vectors (``--gyro-vector``, seeds/002)
become nadir circles through :meth:`NadirCircle.from_gyro_vector`, and the fix gets the
paper's linear error model (:mod:`dracc.math.freegyro`, :func:`free_gyro_model`)."""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dracc.core.arrays import FloatArray
from dracc.core.errors import GeometryError
from dracc.ingest.observations import DatumRecord, ObsSpec, read_observations
from dracc.math.fix import FixReport, fix_report
from dracc.math.freegyro import (
    DopFigures,
    dop_figures,
    position_covariance,
    position_rows,
    z_covariance,
)
from dracc.math.fusion import NadirCircle


def run_fix(
    options: Sequence[tuple[str, Sequence[str]]],
    file: Path | None,
    prior: str | None,
    weighted: bool = True,
) -> FixReport:
    """The fix from the repeated observation ``options`` (``("--range", [...])`` ...),
    the TOML ``file`` and the ``prior`` position text."""
    observations, prior_deg = read_observations(options, file, prior)
    return fix_report(gyro_vectors_as_nadir(observations, []), prior_deg, weighted=weighted)


def run_fix_datums(
    options: Sequence[tuple[str, Sequence[str]]],
    file: Path | None,
    prior: str | None,
    weighted: bool = True,
    datum: str | None = None,
    gyro: list[ObsSpec] | None = None,
) -> tuple[FixReport, tuple[DatumRecord, ...]]:
    """:func:`run_fix` with ``datum`` (``--datum``: the options' datum) and the datum
    transformations applied before fusion, one per transformed observation; the
    gyro-vector observations go to ``gyro``."""
    observations, prior_deg = read_observations(options, file, prior, datum)
    records: list[DatumRecord] = []

    def noted(specs: Iterator[ObsSpec]) -> Iterator[ObsSpec]:
        for spec in specs:  # still lazy: each is checked when the fix asks for it
            if spec.datum is not None:
                records.append(spec.datum)
            yield spec

    specs = gyro_vectors_as_nadir(noted(observations), [] if gyro is None else gyro)
    rep = fix_report(specs, prior_deg, weighted=weighted)
    return rep, tuple(records)


# ------------------------------------------------------------ gyro vectors (seeds/002)


def gyro_vectors_as_nadir(specs: Iterator[ObsSpec], found: list[ObsSpec]) -> Iterator[ObsSpec]:
    """Each gyro-vector observation as the nadir circle of (1) about the sub-point that
    :meth:`NadirCircle.from_gyro_vector` gives (still lazy); the originals go to ``found``."""
    for spec in specs:
        if spec.kind == "gyro_vector":
            found.append(spec)
            v = spec.values
            u = (v["ux"], v["uy"], v["uz"])
            try:
                c = NadirCircle.from_gyro_vector(u, v["time_s"], math.radians(v["nadir_deg"]), 1.0)
            except GeometryError as e:
                raise GeometryError(f"{spec.source} {spec.text!r}: {e}") from None
            sub = (math.degrees(c.sub_lat_rad), math.degrees(c.sub_lon_rad))
            spec = replace(
                spec, kind="nadir", points_deg=(sub,), values={"nadir_deg": v["nadir_deg"]}
            )
        yield spec


@dataclass(frozen=True)
class FreeGyroModel:
    """The paper's error model of the gyro vectors at the fused position (docs/free-gyro.md).

    ``labels``: the gyro vectors; ``sigma_theta_deg``, ``sigma_u_deg`` their nadir and
    direction sigmas, ``sigma_t_s`` the one clock's (the largest given); ``dop`` both DOP
    figures (:class:`DopFigures`); ``cov_m2`` the north/east covariance of (33) from these
    inputs and ``drms_m`` its sqrt(trace); None with ``reason`` when the gyro vectors alone
    do not fix both coordinates.
    """

    labels: tuple[str, ...]
    sigma_theta_deg: tuple[float, ...]
    sigma_u_deg: tuple[float, ...]
    sigma_t_s: float
    dop: DopFigures | None
    cov_m2: FloatArray | None
    drms_m: float | None
    reason: str | None


def free_gyro_model(rep: FixReport, gyro: Sequence[ObsSpec]) -> FreeGyroModel | None:
    """(30)-(38) for the gyro-vector observations ``gyro`` at ``rep``'s position (None if none)."""
    if not gyro:
        return None
    u = np.array([[g.values[k] for k in ("ux", "uy", "uz")] for g in gyro])
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    t = np.array([g.values["time_s"] for g in gyro])
    s_theta = tuple(g.sigma for g in gyro)
    s_u = tuple(g.values["sigma_u_deg"] for g in gyro)
    s_t = max(g.values["sigma_t_s"] for g in gyro)
    labels = tuple(g.label for g in gyro)
    lat, lon = float(rep.solution.lat_rad), float(rep.solution.lon_rad)
    try:
        rows = position_rows(u, lat, lon, t)
        cov_z = z_covariance(rows, np.diag(np.radians(s_theta) ** 2), np.radians(s_u), s_t)
        _, cov_m2 = position_covariance(rows, cov_z, lat)
        dop = dop_figures(u, lat, lon, t)
    except GeometryError:
        reason = (
            "one gyro vector cannot fix both coordinates"
            if len(gyro) == 1
            else "the gyro vectors alone do not fix both coordinates (their circles are tangent)"
        )
        return FreeGyroModel(labels, s_theta, s_u, s_t, None, None, None, reason)
    drms = float(np.sqrt(np.trace(cov_m2)))
    return FreeGyroModel(labels, s_theta, s_u, s_t, dop, cov_m2, drms, None)


def run_fix_free_gyro(
    options: Sequence[tuple[str, Sequence[str]]],
    file: Path | None,
    prior: str | None,
    weighted: bool = True,
    datum: str | None = None,
) -> tuple[FixReport, tuple[DatumRecord, ...], FreeGyroModel | None]:
    """:func:`run_fix_datums` and the free-gyro error model of the gyro vectors given."""
    found: list[ObsSpec] = []
    rep, records = run_fix_datums(options, file, prior, weighted, datum, found)
    return rep, records, free_gyro_model(rep, found)
