"""Issue 29, item 4: ``analyze -c`` takes every configuration ``audit`` takes (one path).

``dracc analyze -c berth.toml LOG`` with a ``[reference] alongside`` berth exited 2
("expected a table ..., got BerthConfig"): the options were merged into the validated
configuration and validated again, and a berth already built was not a table.  The same
file worked in ``dracc audit``.
"""

from __future__ import annotations

import json

from conftest import SAMPLES

from dracc.core.config import config_from_dict, validate
from dracc.core.errors import ExitCode

LOG = SAMPLES / "voyage_tag.nmea"  # 3 h, 54.6 N 18.8 E, 2026-03-01 06:00-09:00 UTC

#: every section dracc knows, and two berths (one with its period, TOML date-times unquoted)
BERTH_TOML = """
[ingest]
sources = { GYRO = "compass" }
gap_s = 120

[dead_reckoning]
reset = "1h"
compass_bias_deg = { sigma = 0.4, tau_s = "inf" }
log_scale = 0.01
deviation_table = { "0" = 0.5, "90" = -0.5 }

[deviation]
interval_s = 1800
apriori = { ins1 = { lat_m = 300.0, lon_m = 400.0, course_deg = 0.1 } }

[faults]
max_speed_kn = 50

[integrity]
false_alarm = 0.001

[reference]
[[reference.alongside]]
pier = [54.6000, 18.8000, 54.6010, 18.8000]
side = "starboard"
half_breadth_m = 10.0
heading_deg = 0.0
abeam = [54.6005, 18.8000]
start_utc = 2026-02-27T08:00:00Z
end_utc = 2026-02-28T08:00:00Z

[[reference.alongside]]
pier = [54.7000, 18.9000, 54.7000, 18.9020]
side = "port"
half_breadth_m = 11.5

[audit]
vessel = "Berth test"
log_scale_max_pct = 2.0
required_sources = ["compass", "log", "gnss", "ins1", "ins2", "ins3"]

[vessel]
name = "Berth test"
"""


def test_analyze_takes_audit_berth_config(run_cli, tmp_path):
    cfg = tmp_path / "berth.toml"
    cfg.write_text(BERTH_TOML, encoding="utf-8")
    # the audit took this file before the fix; it still does
    code, out, err = run_cli("audit", LOG, "-c", cfg, "--db", tmp_path / "s.sqlite")
    assert code in (ExitCode.OK, ExitCode.FINDINGS), err
    assert "dracc audit: Berth test" in out
    # analyze exited 2 ("got BerthConfig"); with options merged too (validated again)
    for extra in ((), ("--dr-reset", "30min", "--probability", "0.9", "--role", "LOG=log")):
        code, _out, err = run_cli("analyze", LOG, "-c", cfg, "--json", tmp_path / "a.json", *extra)
        assert code == ExitCode.OK, err
        doc = json.loads((tmp_path / "a.json").read_text())
        said = " ".join(doc["missing"] + doc["deviation"]["messages"])
        # both berths reached the analysis (the ship lay at neither: said, per berth)
        assert "alongside[0]" in said and "alongside[1]" in said, said
    # a file's error is still the file's (exit 4), named by its key, in both commands
    bad = tmp_path / "bad.toml"
    bad.write_text(BERTH_TOML.replace('side = "port"', 'side = "aft"'), encoding="utf-8")
    for cmd in (("analyze", LOG), ("audit", LOG, "--db", tmp_path / "s.sqlite")):
        code, _out, err = run_cli(*cmd, "-c", bad)
        assert code == ExitCode.CONFIG and "side" in err and "alongside" in err, err


def test_validation_is_idempotent_for_every_section():
    import sys

    tomllib = __import__("tomllib" if sys.version_info >= (3, 11) else "tomli")
    cfg = config_from_dict(tomllib.loads(BERTH_TOML))
    assert validate(cfg) == cfg
    assert validate(validate(cfg)) == cfg
    assert len(cfg.reference.alongside) == 2
