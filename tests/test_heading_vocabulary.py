"""Issue 13: the heading ``reference`` as real writers spell it (JSON, CSV, protobuf,
ROS 2); anything else counted and reported, never read as magnetic or true by accident."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import SAMPLES

from dracc.core.config import Config, IngestConfig
from dracc.frames import Rejects
from dracc.ingest.csv import read_csv
from dracc.ingest.csv_quantities import build_frames
from dracc.ingest.mcap import read_mcap
from dracc.ingest.references import (
    REJECT_REASON,
    normalize_boolean,
    normalize_reference,
    ros_constants,
)

CFG = IngestConfig()
T0 = 1_700_000_000_000_000_000


@pytest.mark.parametrize(
    "spelling, want",
    [
        ("T", "T"),
        ("t", "T"),
        ("true", "T"),
        ("TRUE", "T"),
        (" True ", "T"),
        ("true_north", "T"),
        ("True North", "T"),
        ("geographic", "T"),
        (84, "T"),
        (84.0, "T"),
        ("M", "M"),
        ("m", "M"),
        ("magnetic", "M"),
        ("MAGNETIC", "M"),
        ("Magnetic_North", "M"),
        ("mag", "M"),
        (77, "M"),
    ],
)
def test_accepted_spellings(spelling, want):
    ref, bad = normalize_reference([spelling])
    assert ref.tolist() == [want] and not bad.any()


@pytest.mark.parametrize("spelling", ["grid", "UTM", "north", "x", True, False, 1, 0, 3.5, "tru"])
def test_other_values_are_not_understood(spelling):
    ref, bad = normalize_reference([spelling])
    assert ref.tolist() == [None] and bad.tolist() == [True]


def test_absent_values_are_not_given_not_bad():
    ref, bad = normalize_reference([None, "", "  ", math.nan])
    assert ref.tolist() == [None] * 4 and not bad.any()


def test_booleans():
    ref, bad = normalize_boolean([True, False, "true", "FALSE", 1, 0, None, "maybe"], "T")
    assert ref.tolist() == ["T", "M", "T", "M", "T", "M", None, None]
    assert bad.tolist() == [False] * 7 + [True]
    ref, _ = normalize_boolean([True, False], "M")
    assert ref.tolist() == ["M", "T"]


def test_ros_constants_from_a_message_definition():
    azimuth = (
        "float64 azimuth\nuint8 REFERENCE_MAGNETIC=0\nuint8 REFERENCE_GEOGRAPHIC=1\n"
        "uint8 REFERENCE_UTM=2\nuint8 reference\n"
    )
    assert ros_constants(azimuth) == {0: "M", 1: "T", 2: None}
    assert ros_constants("uint8 reference  # 84 'T' true, 77 'M' magnetic\n") == {}


def test_build_frames_counts_and_shows_what_it_cannot_read():
    n = 5
    rej = Rejects()
    fr = build_frames(
        T0 + np.arange(n),
        "GYRO",
        np.arange(1, n + 1),
        "csv",
        {
            "heading_deg": np.full(n, 10.0),
            "reference": np.array(["true", "Magnetic", "grid", None, "T"], dtype=object),
        },
        "f.csv",
        rej,
    )
    h = fr["heading"]
    assert h["line"].tolist() == [1, 2, 4, 5]  # the 'grid' record is not used
    assert (
        h["reference"].astype(object).tolist()[:2] == ["T", "M"]
        and h["reference"].isna().tolist()[2]
    )
    assert rej.counts[REJECT_REASON] == 1
    assert rej.examples[REJECT_REASON][0][1] == 3 and "grid" in rej.examples[REJECT_REASON][0][2]


def test_two_fields_that_disagree_are_not_understood():
    rej = Rejects()
    fr = build_frames(
        T0 + np.arange(2),
        "GYRO",
        np.array([1, 2]),
        "json",
        {
            "heading_deg": np.array([1.0, 2.0]),
            "reference": np.array(["T", "T"], dtype=object),
            "is_magnetic": np.array([False, True], dtype=object),
        },
        "f",
        rej,
    )
    assert fr["heading"]["line"].tolist() == [1] and rej.counts[REJECT_REASON] == 1


def test_csv_wide_and_long_read_the_words(tmp_path):
    wide = tmp_path / "w.csv"
    wide.write_text(
        "time,source,heading_deg,reference\n"
        "2026-03-01T00:00:00Z,GYRO,10,true\n2026-03-01T00:00:01Z,GYRO,11,MAGNETIC\n"
        "2026-03-01T00:00:02Z,GYRO,12,grid\n"
    )
    r = read_csv(wide, CFG)
    assert r.frames["heading"]["reference"].astype(object).tolist() == ["T", "M"]
    assert r.rejects.counts[REJECT_REASON] == 1
    long = tmp_path / "l.csv"
    long.write_text(
        "time,source,quantity,value\n"
        "2026-03-01T00:00:00Z,GYRO,heading_deg,10\n2026-03-01T00:00:00Z,GYRO,is_true,true\n"
        "2026-03-01T00:00:01Z,GYRO,heading_deg,11\n2026-03-01T00:00:01Z,GYRO,is_true,false\n"
    )
    r = read_csv(long, CFG)
    assert r.frames["heading"]["reference"].astype(object).tolist() == ["T", "M"]


def _json_mcap(path, objs):
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema(name="dracc.Heading", encoding="jsonschema", data=b"{}")
        cid = w.register_channel(topic="/ins1/heading", message_encoding="json", schema_id=sid)
        for i, o in enumerate(objs):
            w.add_message(
                cid,
                log_time=T0 + i * 10**9,
                data=json.dumps(o).encode(),
                publish_time=T0 + i * 10**9,
            )
        w.finish()


def test_mcap_json_words_booleans_and_a_bad_value(tmp_path):
    p = tmp_path / "h.mcap"
    _json_mcap(
        p,
        [
            {"heading_deg": 1.0, "reference": "true"},
            {"heading_deg": 2.0, "reference": "magnetic"},
            {"heading_deg": 3.0, "reference": True},
            {"heading_deg": 4.0, "reference": "T"},
        ],
    )
    r = read_mcap(p, CFG)
    assert r.frames["heading"]["reference"].astype(object).tolist() == ["T", "M", "T"]
    assert r.rejects.counts[REJECT_REASON] == 1
    q = tmp_path / "b.mcap"
    _json_mcap(
        q, [{"heading_deg": 1.0, "true_heading": True}, {"heading_deg": 2.0, "true_heading": False}]
    )
    r = read_mcap(q, CFG)
    assert r.frames["heading"]["reference"].astype(object).tolist() == ["T", "M"]


AZIMUTH = (
    "std_msgs/Header header\nfloat64 heading_deg\nuint8 REFERENCE_MAGNETIC=0\n"
    "uint8 REFERENCE_GEOGRAPHIC=1\nuint8 REFERENCE_UTM=2\nuint8 reference\n"
    + "=" * 80
    + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
)


def test_ros2_reference_constants_from_the_definition(tmp_path):
    from mcap_ros2.writer import Writer

    p = tmp_path / "az.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        sch = w.register_msgdef("compass_msgs/msg/Azimuth", AZIMUTH)
        for i, ref in enumerate([0, 1, 2, 1]):
            w.write_message(
                "/gyro/azimuth",
                sch,
                {
                    "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "g"},
                    "heading_deg": 10.0 + i,
                    "reference": ref,
                },
                log_time=T0 + i * 10**9,
                publish_time=T0 + i * 10**9,
            )
        w.finish()
    r = read_mcap(p, CFG)
    assert r.frames["heading"]["reference"].astype(object).tolist() == ["M", "T", "T"]
    assert r.rejects.counts[REJECT_REASON] == 1  # UTM grid north: declared, not usable


def _rewrite_reference(src, dst, true_word: str, magnetic_word: str) -> None:
    """The simulator's MCAP JSON with its ``"reference":"T"``/``"M"`` respelled."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        w = Writer(g, compression=CompressionType.NONE)
        w.start()
        schemas, channels, n = {}, {}, 0
        for schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(
                    channel.topic, channel.message_encoding, schemas[schema.id]
                )
            data = msg.data.replace(b'"reference":"T"', b'"reference":"%s"' % true_word.encode())
            data = data.replace(b'"reference":"M"', b'"reference":"%s"' % magnetic_word.encode())
            n += data != msg.data
            w.add_message(channels[channel.id], msg.log_time, data, msg.publish_time, msg.sequence)
        w.finish()
    assert n > 1000  # the rewrite did something


@pytest.fixture(scope="module")
def nmea_figures():
    from test_same_analysis_any_container import _figures

    from dracc.pipeline.analysis import analyse
    from dracc.report.json_report import to_dict

    return _figures(to_dict(analyse([SAMPLES / "voyage_tag.nmea"], Config())))


@pytest.mark.parametrize("words", [("true", "magnetic"), ("TRUE", "Magnetic")])
def test_mcap_json_true_gives_the_statistics_of_the_nmea_form(tmp_path, nmea_figures, words):
    """The issue's case: an INS triple in MCAP JSON with "reference": "true" kept its
    heading but lost its course channel without a word."""
    from test_same_analysis_any_container import _figures

    from dracc.pipeline.analysis import analyse
    from dracc.report.json_report import to_dict

    p = tmp_path / "v.mcap"
    _rewrite_reference(SAMPLES / "voyage.mcap", p, *words)
    got = _figures(to_dict(analyse([p], Config())))
    assert got.keys() == nmea_figures.keys()
    assert any(k.endswith("course.m_u") for k in got)
    for key, value in nmea_figures.items():
        assert got[key] == pytest.approx(value, rel=1e-6, abs=1e-6), key


# ----------------------------------------------------- issue 13: --variation over 0.0,E
def _nmea(body: str) -> str:
    x = 0
    for b in body.encode():
        x ^= b
    return f"${body}*{x:02X}"


def _hdg_voyage(tmp_path, variation_fields: list[str]):
    from dracc.ingest import read_logs

    lines = []
    for k, var in enumerate(variation_fields):
        lines.append(f"2026-03-01T00:00:{k:02d}.000Z " + _nmea(f"HCHDG,100.0,0.0,E,{var}"))
    p = tmp_path / "hdg.log"
    p.write_text("\n".join(lines) + "\n")
    return read_logs([p], CFG)


@pytest.mark.parametrize("configured", [None, 5.0])
def test_configured_variation_wins_over_a_zero_placeholder(tmp_path, configured):
    from dracc.core.config import DeadReckoningConfig
    from dracc.pipeline.selection import heading_series as _heading_series

    v = _hdg_voyage(tmp_path, ["0.0,E", "0.0,E", "2.0,W", ","])
    missing, notes = [], []
    _t, h, desc = _heading_series(v, DeadReckoningConfig(variation_deg=configured), missing, notes)
    got = np.degrees(h)
    if configured is None:
        np.testing.assert_allclose(got, [100.0, 100.0, 98.0, 100.0], atol=1e-9)
        assert any("sends 0.0 at 2 of 4 samples" in n for n in notes)
        assert any("sends none at 1 of 4" in m for m in missing)
    else:
        # the zero fields and the empty one take the configured 5 deg E; the compass's own
        # 2 deg W is kept
        np.testing.assert_allclose(got, [105.0, 105.0, 98.0, 105.0], atol=1e-9)
        assert "variation 5° from the configuration" in desc and not missing
        assert any(
            "configured 5° used at 3 of 4" in n
            and "0.0 (a placeholder) at 2" in n
            and "own non-zero variation kept at 1" in n
            for n in notes
        )


def test_real_hakefjord_zero_variation_and_the_option(real_dir):
    from dataclasses import replace as dc_replace

    from dracc.core.config import DeadReckoningConfig
    from dracc.ingest import read_logs
    from dracc.pipeline.selection import heading_series as _heading_series

    v = read_logs([real_dir / "VDRplayer" / "Hakefjord.txt"], CFG)
    base = _heading_series(v, DeadReckoningConfig(), [], [])
    notes: list[str] = []
    got = _heading_series(v, dc_replace(DeadReckoningConfig(), variation_deg=4.0), [], notes)
    d = np.degrees(np.angle(np.exp(1j * (got[1] - base[1]))))
    np.testing.assert_allclose(d, 4.0, atol=1e-9)
    assert any("the configured 4° used at" in n for n in notes)


@pytest.mark.parametrize("encoding", ["protobuf", "json"])
def test_writer_words_round_trip_through_mcap(tmp_path, encoding):
    """A writer that spells the reference out (protobuf string field, JSON) reads as T/M."""
    from test_csv import voyage_frames

    from dracc.sim.mcap_out import write_mcap

    fr = voyage_frames(n=12)
    h = fr["heading"].copy()
    h["reference"] = np.array(["true", "Magnetic", "TRUE_NORTH", "utm"] * 3, dtype=object)
    p = write_mcap({"heading": h}, None, tmp_path / "h.mcap", encoding=encoding)
    r = read_mcap(p, CFG)
    got = r.frames["heading"].sort_values("time_ns")
    assert got["reference"].astype(object).tolist() == ["T", "M", "T"] * 3
    assert r.rejects.counts[REJECT_REASON] == 3
