"""The fleet ranking: which unit on which ship is worse than its peers, or got worse.

Input: the nightly measures (:mod:`dracc.pipeline.audit.measures`) of every vessel, from
raw logs or from the audit documents ships send ashore — the same figures either way.
Per vessel, unit and quantity:

1. **Nights.** The night's figure in the score domain: ln RMS for the m_y quantities
   (several logs in one night pooled as mean squares weighted by their degrees of
   freedom), the value itself for the others (inverse-variance mean).  Its standard
   error is 1/sqrt(2 dof) for an RMS, the calibration's sigma otherwise.
2. **Learning the scale.** How far the stated errors are from the nights' real scatter
   is learned per quantity from every series of the fleet (the robust scale phi of the
   standardised night-to-night differences, :func:`dracc.math.ranking.difference_scale`;
   a phi below 1 is taken only down to its 95 % upper bound); a quantity without stated errors
   takes the differences' own scale.  The quantity's resolution is a floor.
3. **Peers.** The pooled figure of the last ``peer_nights`` nights against the other
   units of its peer group (:func:`dracc.math.ranking.peer_scores`): the same INS model
   (``[fleet.ranking] models``; by default the same INS position ins1/ins2/ins3, as
   sister ships carry the same kit in the same place), the logs of the same sea area
   (mean positions within ``area_km`` of the log's: currents and sea state bias a log's
   scale alike there) where there are at least ``min_peers`` of them, else the fleet's.
4. **Own history.** The most likely change point of the unit's nightly series
   (:func:`dracc.math.ranking.change_point`) in the direction that is worse.
5. **Control.** The row's p-value is Bonferroni over its two tests, 2 min(p_peer,
   p_change); q-values are Benjamini-Hochberg over every row of the fleet; a row is a
   discovery at q < ``fdr``.  ``since`` names the change's first night where the row is
   a discovery and the change test alone has p < ``fdr``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd

from dracc.core.config import Config
from dracc.core.errors import ConfigError
from dracc.core.numbers import jsonable
from dracc.math.ranking import (
    MAD_EFFICIENCY,
    bh_qvalues,
    change_point,
    difference_scale,
    peer_scores,
)

#: columns of ranking.parquet/.csv, in order
RANKING_COLUMNS = (
    "rank",
    "vessel",
    "ins_unit",  # the INS unit, or the sensor of the quantity (log, compass, dr, a source)
    "quantity",
    "measure_unit",
    "value",
    "peer_median",
    "score",
    "p_value",
    "q_value",
    "discovery",
    "since",
    "peer_p",
    "change_p",
    "peers",
    "peer_group",
    "nights",
    "first_night",
    "last_night",
    "method",
    "evidence",
)

#: columns of the measures table the ranking reads
MEASURE_COLUMNS = (
    "vessel",
    "night",
    "unit",
    "quantity",
    "measure_unit",
    "value",
    "sigma",
    "dof",
    "n",
    "method",
    "lat_deg",
    "lon_deg",
)


@dataclass(frozen=True)
class QuantitySpec:
    """How one quantity is scored: its domain, which direction is worse, its resolution
    (in the score domain) and who its peers are."""

    domain: str  #: 'log' (an RMS) or 'linear'
    direction: int  #: +1 larger is worse, -1 smaller is worse, 0 either way
    resolution: float
    peers: str  #: 'model' (INS model or position), 'area' (sea area), 'role' (same role)


#: the ranked quantities (names as in :data:`dracc.pipeline.audit.measures.QUANTITY_UNITS`)
QUANTITIES = {
    "lat_m_y": QuantitySpec("log", +1, 0.05, "model"),  # 5 % of the RMS
    "lon_m_y": QuantitySpec("log", +1, 0.05, "model"),
    "course_m_y": QuantitySpec("log", +1, 0.05, "model"),
    "log_scale": QuantitySpec("linear", 0, 0.1, "area"),  # 0.1 % of speed
    "compass_error": QuantitySpec("linear", 0, 0.05, "role"),  # 0.05 deg
    "dr_consistency": QuantitySpec("linear", -1, 1.0, "role"),  # 1 % of epochs
    "latency": QuantitySpec("linear", +1, 0.05, "role"),  # 50 ms
    "availability": QuantitySpec("linear", -1, 0.1, "role"),  # 0.1 % of the night
}

#: nights of history kept in a row's evidence
_EVIDENCE_NIGHTS = 60


@dataclass(frozen=True)
class RankingConfig:
    """The ``[fleet.ranking]`` table."""

    fdr: float = 0.05  #: false discovery rate of the ranked list
    peer_nights: int = 7  #: nights pooled for the comparison with peers
    min_peers: int = 3  #: fewest peers a score is computed with
    area_km: float = 1000.0  #: logs whose mean positions lie this close share a sea area
    #: INS model per "VESSEL/unit" or per "unit"; units of one model are peers
    models: dict[str, str] = field(default_factory=dict)


def ranking_config(cfg: Config) -> RankingConfig:
    """Validate ``[fleet.ranking]`` into a :class:`RankingConfig`."""
    fleet = cfg.extra.get("fleet", {})
    table = fleet.get("ranking", {}) if isinstance(fleet, dict) else {}
    if not isinstance(table, dict):
        raise ConfigError("[fleet.ranking] must be a table")
    known = set(asdict(RankingConfig()))
    unknown = set(table) - known
    if unknown:
        raise ConfigError(
            f"[fleet.ranking] unknown key(s): {', '.join(sorted(unknown))}; "
            f"known: {', '.join(sorted(known))}"
        )
    kw: dict = {}
    fdr = table.get("fdr", 0.05)
    if isinstance(fdr, bool) or not isinstance(fdr, (int, float)) or not 0 < fdr < 1:
        raise ConfigError(f"[fleet.ranking] fdr must be a number in (0, 1), got {fdr!r}")
    kw["fdr"] = float(fdr)
    for key in ("peer_nights", "min_peers"):
        if key in table:
            v = table[key]
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"[fleet.ranking] {key} must be a positive integer, got {v!r}")
            kw[key] = v
    if "area_km" in table:
        v = table["area_km"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise ConfigError(f"[fleet.ranking] area_km must be a positive number, got {v!r}")
        kw["area_km"] = float(v)
    if "models" in table:
        m = table["models"]
        if not isinstance(m, dict) or not all(
            isinstance(k, str) and isinstance(v, str) and v for k, v in m.items()
        ):
            raise ConfigError(
                '[fleet.ranking] models must map "VESSEL/unit" or "unit" to a model name'
            )
        kw["models"] = dict(m)
    return RankingConfig(**kw)


# ------------------------------------------------------------------ the nights


def measures_frame(nights: Sequence[tuple[str, str, Mapping]]) -> pd.DataFrame:
    """The measures table from ``(vessel, night, measures)`` triples, ``measures`` as
    :func:`dracc.pipeline.audit.measures.night_measures` gives it."""
    rows = []
    for vessel, night, m in nights:
        pos = (m or {}).get("position") or {}
        for r in (m or {}).get("rows", ()):
            rows.append(
                {
                    "vessel": vessel,
                    "night": night,
                    **{k: r.get(k) for k in MEASURE_COLUMNS[2:10]},
                    "lat_deg": pos.get("lat_deg"),
                    "lon_deg": pos.get("lon_deg"),
                }
            )
    df = pd.DataFrame(rows, columns=list(MEASURE_COLUMNS))
    for c in ("value", "sigma", "dof", "n", "lat_deg", "lon_deg"):
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("float64")
    return df


@dataclass
class _Series:
    vessel: str
    unit: str
    quantity: str
    measure_unit: str
    method: str
    nights: list[str]
    x: np.ndarray  #: score domain
    se: np.ndarray  #: stated standard error in the score domain (NaN: none)
    dof: np.ndarray  #: RMS degrees of freedom (log domain), else NaN
    lat_deg: float
    lon_deg: float


def _pool_night(g: pd.DataFrame, spec: QuantitySpec) -> tuple[float, float, float]:
    """One night's (x, se, dof) from its logs' figures."""
    v = g["value"].to_numpy()
    if spec.domain == "log":
        dof = np.where(np.isfinite(g["dof"].to_numpy()), g["dof"].to_numpy(), 1.0)
        dof = np.maximum(dof, 1e-6)
        ok = v > 0
        if not ok.any():
            return math.nan, math.nan, math.nan
        ms = float(np.sum(dof[ok] * v[ok] ** 2) / np.sum(dof[ok]))
        d = float(np.sum(dof[ok]))
        return 0.5 * math.log(ms), 1.0 / math.sqrt(2.0 * d), d
    s = g["sigma"].to_numpy()
    if np.all(np.isfinite(s) & (s > 0)):
        w = 1.0 / s**2
        return float(np.sum(w * v) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w))), math.nan
    return float(np.mean(v)), math.nan, math.nan


def _series(measures: pd.DataFrame) -> list[_Series]:
    out: list[_Series] = []
    m = measures[measures["quantity"].isin(list(QUANTITIES)) & np.isfinite(measures["value"])]
    for (vessel, unit, quantity), g in m.groupby(["vessel", "unit", "quantity"], sort=True):
        spec = QUANTITIES[str(quantity)]
        nights, xs, ses, dofs = [], [], [], []
        for night, gn in g.groupby("night", sort=True):
            x, se, d = _pool_night(gn, spec)
            if math.isfinite(x):
                nights.append(str(night))
                xs.append(x)
                ses.append(se)
                dofs.append(d)
        if not nights:
            continue
        methods = g["method"].dropna().astype(str)
        out.append(
            _Series(
                str(vessel),
                str(unit),
                str(quantity),
                str(g["measure_unit"].iloc[0]),
                methods.mode().iloc[0] if len(methods) else "",
                nights,
                np.array(xs),
                np.array(ses),
                np.array(dofs),
                float(np.nanmean(g["lat_deg"])) if g["lat_deg"].notna().any() else math.nan,
                float(_circular_mean_deg(g["lon_deg"])),
            )
        )
    return out


def _circular_mean_deg(lon: pd.Series) -> float:
    v = np.radians(lon.dropna().to_numpy(dtype=np.float64))
    if len(v) == 0:
        return math.nan
    return math.degrees(math.atan2(np.mean(np.sin(v)), np.mean(np.cos(v))))


def _night_errors(series: list[_Series], spec: QuantitySpec) -> tuple[list[np.ndarray], dict]:
    """Each series' effective nightly standard error, learned from the fleet (step 2)."""
    with_se = [s for s in series if np.all(np.isfinite(s.se))]
    phis: dict[str, float] = {}
    n_diffs: dict[str, int] = {}
    for method in sorted({s.method for s in with_se}):
        same = [s for s in with_se if s.method == method]
        phi, n_diff = difference_scale([s.x for s in same], [s.se for s in same])
        if not math.isfinite(phi):
            phi = 1.0
        elif phi < 1.0:  # smaller errors than stated: believed only as far as the data show
            phi = min(1.0, phi * math.exp(1.645 / math.sqrt(2.0 * MAD_EFFICIENCY * n_diff)))
            if method == "hat":  # its bounds are the errors; selection makes nights look alike
                phi = 1.0
        phis[method], n_diffs[method] = phi, n_diff
    raw, n_raw = difference_scale([s.x for s in series if not np.all(np.isfinite(s.se))])
    scale = raw if math.isfinite(raw) else spec.resolution
    r2 = spec.resolution**2
    out = []
    for s in series:
        if np.all(np.isfinite(s.se)):
            out.append(np.sqrt((phis[s.method] * s.se) ** 2 + r2))
        else:
            out.append(np.full(len(s.x), math.sqrt(scale**2 + r2)))
    return out, {"phi": phis, "differences": n_diffs, "scale": scale, "scale_differences": n_raw}


def _change_df(learned: dict, s: _Series) -> float:
    """Degrees of freedom of the change statistic's scale: 0.37 per difference it was
    learned from (the MAD's efficiency), at least 3."""
    stated = bool(np.all(np.isfinite(s.se)))
    n = learned["differences"].get(s.method, 0) if stated else learned["scale_differences"]
    return max(3.0, MAD_EFFICIENCY * n) if n else 3.0


def _constant(series: list[_Series], spec: QuantitySpec) -> bool:
    """True when every night of every unit lies within the resolution of every other:
    tests of such a quantity cannot find anything, and would only dilute the FDR (a
    filter blind to which unit is tested: Bourgon, Gentleman & Huber 2010)."""
    x = np.concatenate([s.x for s in series])
    return bool(np.nanmax(x) - np.nanmin(x) < spec.resolution)


def _pooled(s: _Series, se: np.ndarray, k: int, spec: QuantitySpec) -> tuple[float, float]:
    """The last ``k`` nights pooled: (x, se) in the score domain."""
    x, e = s.x[-k:], se[-k:]
    if spec.domain == "log":
        d = np.where(np.isfinite(s.dof[-k:]), s.dof[-k:], 1.0)
        ms = np.sum(d * np.exp(2 * x)) / np.sum(d)
    else:
        ms = None
    w = 1.0 / e**2
    if ms is not None:
        return 0.5 * math.log(ms), float(1.0 / math.sqrt(np.sum(w)))
    return float(np.sum(w * x) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w)))


def _peer_group(s: _Series, spec: QuantitySpec, rc: RankingConfig) -> str:
    if spec.peers == "model":
        return rc.models.get(f"{s.vessel}/{s.unit}") or rc.models.get(s.unit) or s.unit
    if spec.peers == "area":
        return "sea area"
    return s.unit


def _area_peers(series: list[_Series], rc: RankingConfig) -> tuple[np.ndarray, list[str]]:
    """Each log's peers: the logs whose mean positions lie within ``area_km`` of its own
    (great circle); the whole fleet's where fewer than ``min_peers`` do, or where the
    position is not known."""
    lat = np.radians([s.lat_deg for s in series])
    lon = np.radians([s.lon_deg for s in series])
    dlat = lat[:, None] - lat[None, :]
    dlon = lon[:, None] - lon[None, :]
    h = np.sin(dlat / 2) ** 2 + np.cos(lat[:, None]) * np.cos(lat[None, :]) * np.sin(dlon / 2) ** 2
    with np.errstate(invalid="ignore"):
        dist_km = 2 * 6371.0088 * np.arcsin(np.sqrt(np.clip(h, 0, 1)))
    near = dist_km <= rc.area_km
    names = []
    for i in range(len(series)):
        if np.count_nonzero(near[i]) - 1 < rc.min_peers:
            near[i] = True
            names.append("fleet")
        else:
            names.append(f"within {rc.area_km:g} km")
    return near, names


def _natural(x: float, spec: QuantitySpec) -> float:
    return math.exp(x) if spec.domain == "log" and math.isfinite(x) else x


def _f(x) -> float | None:
    return float(x) if x is not None and math.isfinite(float(x)) else None


def rank_fleet(measures: pd.DataFrame, rc: RankingConfig | None = None) -> pd.DataFrame:
    """The ranked list (:data:`RANKING_COLUMNS`), the strongest evidence first."""
    rc = rc or RankingConfig()
    rows: list[dict] = []
    all_series = _series(measures)
    for quantity, spec in QUANTITIES.items():
        series = [s for s in all_series if s.quantity == quantity]
        if not series:
            continue
        if _constant(series, spec):
            continue  # no unit differs from another: nothing to rank (independent filtering)
        se_list, learned = _night_errors(series, spec)
        k = rc.peer_nights
        pooled = [_pooled(s, e, k, spec) for s, e in zip(series, se_list, strict=True)]
        groups = [_peer_group(s, spec, rc) for s in series]
        peers_of = None
        if spec.peers == "area":
            peers_of, groups = _area_peers(series, rc)
        ps = peer_scores(
            [p[0] for p in pooled],
            [p[1] for p in pooled],
            np.array(groups, dtype=object),
            direction=spec.direction,
            resolution=spec.resolution,
            min_peers=rc.min_peers,
            peers_of=peers_of,
        )
        natural = np.array([_natural(p[0], spec) for p in pooled], dtype=np.float64)
        for i, s in enumerate(series):
            peer_median = _peer_median(natural, ps, i)
            cp = change_point(
                s.x,
                se_list[i],
                direction=spec.direction,
                df=_change_df(learned, s),
            )
            z = ps.z[i]
            score = z * spec.direction if spec.direction else z
            evidence = {
                "method": s.method,
                "peer_group": groups[i],
                "learned": learned,
                "nights": [
                    {
                        "night": n,
                        "value": _f(_natural(x, spec)),
                        "se": _f(e),
                    }
                    for n, x, e in list(zip(s.nights, s.x, se_list[i], strict=True))[
                        -_EVIDENCE_NIGHTS:
                    ]
                ],
                "peer": {
                    "window_nights": min(k, len(s.nights)),
                    "value": _f(_natural(pooled[i][0], spec)),
                    "median": _f(peer_median),
                    "mean": _f(_natural(ps.center[i], spec)),  # the score's centre
                    "spread": _f(ps.spread[i]),
                    "peers": int(ps.peers[i]),
                    "z": _f(z),
                    "df": _f(ps.df[i]),
                    "p": _f(ps.p[i]),
                },
                "change": {
                    "night": s.nights[cp.index] if cp.index >= 0 else None,
                    "before": _f(_natural(cp.before, spec)),
                    "after": _f(_natural(cp.after, spec)),
                    "z": _f(cp.z),
                    "splits": cp.splits,
                    "p": _f(cp.p),
                },
            }
            rows.append(
                {
                    "vessel": s.vessel,
                    "ins_unit": s.unit,
                    "quantity": quantity,
                    "measure_unit": s.measure_unit,
                    "value": _natural(pooled[i][0], spec),
                    "peer_median": peer_median,
                    "score": score,
                    "peer_p": ps.p[i],
                    "change_p": cp.p,
                    "_change_night": s.nights[cp.index] if cp.index >= 0 else None,
                    "peers": int(ps.peers[i]),
                    "peer_group": groups[i],
                    "nights": len(s.nights),
                    "first_night": s.nights[0],
                    "last_night": s.nights[-1],
                    "method": s.method,
                    "evidence": evidence,
                }
            )
    return _controlled(rows, rc)


def _peer_median(natural: np.ndarray, ps, i: int) -> float:
    """The median of the values (in their own unit: an RMS, not its log) of the peers
    unit ``i`` was compared with; NaN where it had too few."""
    if ps.compared is None or not np.isfinite(ps.z[i]):
        return math.nan
    return float(np.median(natural[ps.compared[i]]))


def _controlled(rows: list[dict], rc: RankingConfig) -> pd.DataFrame:
    """Combine each row's two tests, control the FDR over the fleet, rank, type."""
    if not rows:
        return _typed(pd.DataFrame(columns=list(RANKING_COLUMNS)))
    df = pd.DataFrame(rows)
    pp = df["peer_p"].to_numpy(dtype=np.float64)
    cp = df["change_p"].to_numpy(dtype=np.float64)
    both = np.fmin(pp, cp)  # NaN only where neither test could be made
    tests = np.isfinite(pp).astype(int) + np.isfinite(cp).astype(int)
    df["p_value"] = np.minimum(1.0, both * np.maximum(tests, 1))
    df["q_value"] = bh_qvalues(df["p_value"].to_numpy())
    df["discovery"] = df["q_value"] < rc.fdr
    changed = df["discovery"] & (df["change_p"] < rc.fdr)
    df["since"] = df["_change_night"].where(changed, None)
    for i in df.index:
        ev = df.at[i, "evidence"]
        ev["q"] = _f(df.at[i, "q_value"])
        since = df.at[i, "since"]
        ev["since"] = since if isinstance(since, str) else None
        df.at[i, "evidence"] = json.dumps(jsonable(ev), ensure_ascii=False, allow_nan=False)
    df["_absscore"] = -df["score"].abs().fillna(0.0)
    df = df.sort_values(
        ["q_value", "p_value", "_absscore", "vessel", "ins_unit", "quantity"],
        na_position="last",
        kind="mergesort",
    ).reset_index(drop=True)
    df["rank"] = np.arange(1, len(df) + 1)
    return _typed(df[list(RANKING_COLUMNS)].copy())


def _typed(df: pd.DataFrame) -> pd.DataFrame:
    for c in ("value", "peer_median", "score", "p_value", "q_value", "peer_p", "change_p"):
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("float64")
    for c in ("rank", "peers", "nights"):
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("Int64")
    df["discovery"] = df["discovery"].astype("boolean")
    for c in ("first_night", "last_night", "since"):
        df[c] = pd.to_datetime(df[c], format="%Y-%m-%d", errors="coerce").dt.date
        df[c] = df[c].astype("date32[pyarrow]")
    for c in ("vessel", "ins_unit", "quantity", "measure_unit", "peer_group", "method", "evidence"):
        df[c] = df[c].astype("string")
    return df
