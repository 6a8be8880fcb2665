"""Role assignment: configuration first, then names, then unambiguous content."""

from __future__ import annotations

from collections import Counter

import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import AmbiguousSourceError, ConfigError
from dracc.frames import SourceInfo
from dracc.ingest import read_logs
from dracc.ingest.sources import assign_roles, require_role


def src(key: str, talker: str, **sentences: int) -> SourceInfo:
    return SourceInfo(
        key=key,
        talkers=Counter({talker: sum(sentences.values())}),
        sentences=Counter(sentences),
        records=sum(sentences.values()),
    )


def roles(sources):
    return {k: s.role for k, s in sources.items()}


def test_tag_names_give_roles():
    s = {
        k: src(k, t, **sn)
        for k, t, sn in [
            ("INS1", "IN", {"GGA": 5, "HDT": 5}),
            ("INS2", "IN", {"GGA": 5}),
            ("INS3", "IN", {"GGA": 5}),
            ("GYRO", "HE", {"HDT": 50}),
            ("LOG", "VW", {"VHW": 5}),
            ("GNSS", "GP", {"GGA": 5, "RMC": 5}),
        ]
    }
    assign_roles(s, {})
    assert roles(s) == {
        "INS1": "ins1",
        "INS2": "ins2",
        "INS3": "ins3",
        "GYRO": "compass",
        "LOG": "log",
        "GNSS": "gnss",
    }


def test_three_ins_talkers_and_satellite_talker_by_content():
    s = {k: src(k, k, GGA=5, HDT=5) for k in ("IN", "II", "IR")}
    s["GN"] = src("GN", "GN", GGA=5, RMC=5)
    s["HC"] = src("HC", "HC", HDG=5)
    assign_roles(s, {})
    assert roles(s) == {"II": "ins1", "IN": "ins2", "IR": "ins3", "GN": "gnss", "HC": "compass"}


def test_instrument_bus_serves_compass_and_log():
    s = {"II": src("II", "II", HDG=5, VHW=5, RMC=5)}
    notes = assign_roles(s, {})
    assert s["II"].roles == ["compass", "log"] and s["II"].role == "compass+log"
    assert any("II -> log" in n for n in notes)


def test_config_mapping_by_key_and_by_talker_first():
    s = {
        "GP/3dp": src("GP/3dp", "GP", RMC=5, GGA=5),
        "GP/5dp": src("GP/5dp", "GP", RMC=5),
        "II": src("II", "II", HDG=5, VHW=5, RMC=5),
    }
    assign_roles(s, {"GP/3dp": "gnss", "II": "ins1"})
    assert roles(s) == {"GP/3dp": "gnss", "GP/5dp": None, "II": "ins1"}
    s = {"x": src("x", "HE", HDT=5)}
    assign_roles(s, {"HE": "compass"})  # a talker ID in the mapping
    assert s["x"].roles == ["compass"]


def test_ambiguous_candidates_are_handed_back_not_guessed():
    """On counts alone nothing is guessed: the candidates go to the evidence of the values."""
    s = {
        "GP/3dp": src("GP/3dp", "GP", RMC=5),
        "GP/5dp": src("GP/5dp", "GP", RMC=5),
        "HE": src("HE", "HE", HDT=5),
        "HN": src("HN", "HN", THS=5),
    }
    candidates: dict[str, list[str]] = {}
    assign_roles(s, {}, candidates)
    assert all(v is None for v in roles(s).values())
    assert candidates == {"gnss": ["GP/3dp", "GP/5dp"], "compass": ["HE", "HN"]}
    with pytest.raises(AmbiguousSourceError, match="no source has role gnss"):
        require_role(s, "gnss")


def test_mapping_errors():
    s = {"A": src("A", "IN", GGA=1), "B": src("B", "IN", GGA=1)}
    with pytest.raises(AmbiguousSourceError, match="ins1 given to several sources: A, B"):
        assign_roles(s, {"A": "ins1", "B": "ins1"})
    with pytest.raises(ConfigError, match="role must be one of"):
        assign_roles({"A": src("A", "IN", GGA=1)}, {"A": "radar"})
    notes = assign_roles({"A": src("A", "IN", GGA=1)}, {"ZZ": "gnss"})
    assert any("'ZZ' matches no source" in n for n in notes)


def test_roles_from_config_through_read_logs(real_dir):
    v = read_logs(
        [real_dir / "VDRplayer" / "Hakefjord.txt"], IngestConfig(sources={"GP/3dp": "gnss"})
    )
    assert v.role_sources("gnss") == ["GP/3dp"] and set(v.role_sources("compass")) == {"II"}
    assert len(v.frame("position", "gnss")) > 600


def test_heading_only_source_is_the_compass_beside_an_ins_talker():
    # prefix-form logs: three INS behind one talker IN (GGA + HDT) and a gyro HE (HDT only)
    s = {
        "IN": src("IN", "IN", GGA=30, HDT=30, VTG=30),
        "HE": src("HE", "HE", HDT=100),
        "GP": src("GP", "GP", GGA=10, RMC=10),
    }
    assign_roles(s, {})
    assert roles(s) == {"IN": None, "HE": "compass", "GP": "gnss"}


def test_gyro_and_magnetic_compass_both_candidates_for_the_evidence():
    """Two heading sources: neither given the role on counts alone; both handed back as
    candidates (the evidence of the values chooses one: tests/test_role_evidence.py)."""
    s = {"HE": src("HE", "HE", HDT=100, ROT=10), "HC": src("HC", "HC", HDG=100)}
    candidates: dict[str, list[str]] = {}
    assign_roles(s, {}, candidates)
    assert roles(s) == {"HE": None, "HC": None}
    assert candidates == {"compass": ["HC", "HE"]}
