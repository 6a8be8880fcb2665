"""NMEA 2000 inside NMEA 0183 ($PCDIN) among the sentences of one log: decoded, merged,
timed by the sentences around them, and the same values as the plain canboat log."""

from __future__ import annotations

import numpy as np
from conftest import real_path

from dracc.core.config import IngestConfig
from dracc.ingest import detect_format, read_file


def _sentence(body: str) -> str:
    x = 0
    for c in body.encode():
        x ^= c
    return f"${body}*{x:02X}"


def _rmc(second: int) -> str:
    return _sentence(f"GPRMC,1900{second:02d}.00,A,5943.5,N,02444.2,E,5.0,90.0,150814,,,A")


def test_pcdin_lines_in_a_0183_log_give_the_plain_logs_values(tmp_path):
    plain = real_path("signalk-server", "aava-n2k.data")
    rows = [ln.split(",") for ln in plain.read_text().splitlines()[:400]]
    nav = [r for r in rows if r[2] in ("127250", "128259", "129025")][:60]
    lines = []
    for k, r in enumerate(nav):
        lines.append(_rmc(k))
        lines.append(_sentence("GPVTG,90.0,T,,M,5.0,N,9.3,K,A"))
        pgn, src, data = int(r[2]), int(r[3]), "".join(r[6:]).upper()
        lines.append(_sentence(f"PCDIN,{pgn:06X},{k:08X},{src:02X},{data}"))
    p = tmp_path / "mixed.nmea"
    p.write_text("\r\n".join(lines) + "\r\n")
    assert detect_format(p) == "nmea"  # a few $PCDIN lines: still an NMEA 0183 log
    r = read_file(p, IngestConfig())
    ref = read_file(plain, IngestConfig())
    assert r.rejects.total == 0 and "PCDIN" not in r.ignored
    for kind, col in (("heading", "heading_rad"), ("water", "stw_mps"), ("position", "lat_rad")):
        got = r.frames[kind]
        got = got[got["sentence"].astype(str).str.startswith("PGN")]
        want = ref.frames[kind]
        want = want[want["line"].isin([int(i) + 1 for i, x in enumerate(rows) if x in nav])]
        n = sum(
            1 for x in nav if x[2] == {"heading": "127250", "water": "128259"}.get(kind, "129025")
        )
        assert len(got) == n > 0, kind
        np.testing.assert_allclose(
            np.sort(got[col].to_numpy()), np.sort(want[col].to_numpy()[: len(got)]), rtol=1e-12
        )
    # each message takes the time of the RMC before it (rule 3)
    pos = r.frames["position"]
    n2k = pos[pos["sentence"].astype(str) == "PGN129025"]
    rmc_t = pos[pos["sentence"].astype(str) == "RMC"].set_index("line")["time_ns"]
    for line, t in zip(n2k["line"], n2k["time_ns"], strict=True):
        assert t == rmc_t[rmc_t.index < line].iloc[-1]
    assert any("$PCDIN" in n for n in r.notes)
