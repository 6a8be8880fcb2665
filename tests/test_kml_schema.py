"""Every KML dracc writes (``dracc analyze --kml``) validates against the official OGC KML
2.2 schema (``tests/data/kml22/``, bundled: see its README), on a shipped sample and on a
simulated voyage with a GNSS jump (the 2M misses folder), and in the shapes an analysis
can take (no DR, no aided EP, hostile source names).

Google's ``gx:`` elements (a ``gx:Track`` per leg: the time slider) are not in the OGC
schema.  Google's own schema (kml22gx.xsd) puts each in one of the OGC schema's extension
slots by substitution group; the OGC schema validates a document in which each outermost
``gx:`` element is replaced by a stand-in element of *that* slot, so a ``gx:`` element
written anywhere else (before the styles, inside a ``Style``, beside a ``Folder``) fails.
Inside them, the order of Google's KML reference is checked by hand
(:func:`_check_gx_content`).
"""

from __future__ import annotations

import copy
import types
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import SAMPLES, SPARSE_RATES

from dracc.core.errors import ExitCode

etree = pytest.importorskip("lxml.etree")

XSD = Path(__file__).resolve().parent / "data" / "kml22"
KML = "{http://www.opengis.net/kml/2.2}"
GX = "{http://www.google.com/kml/ext/2.2}"
SLOT = "urn:dracc:test:gx-slot"

#: the OGC extension slot of each gx element dracc writes outermost, as Google's schema
#: (kml22gx.xsd) declares its substitution group
GX_SLOTS = {
    "Track": "Geometry",  # kml:AbstractGeometryGroup
    "MultiTrack": "Geometry",
    "SimpleArrayField": "SchemaExtension",  # kml:SchemaExtension, inside kml:Schema
    "SimpleArrayData": "SchemaDataExtension",  # kml:SchemaDataExtension, inside kml:SchemaData
}

#: a schema of stand-ins, one per slot, on top of the OGC schema
STAND_INS = f"""<schema xmlns="http://www.w3.org/2001/XMLSchema"
  xmlns:kml="http://www.opengis.net/kml/2.2" targetNamespace="{SLOT}"
  elementFormDefault="qualified">
  <import namespace="http://www.opengis.net/kml/2.2" schemaLocation="ogckml22.xsd"/>
  <element name="Geometry" substitutionGroup="kml:AbstractGeometryGroup">
    <complexType><complexContent><extension base="kml:AbstractGeometryType"/>
    </complexContent></complexType>
  </element>
  <element name="SchemaExtension" substitutionGroup="kml:SchemaExtension"/>
  <element name="SchemaDataExtension" substitutionGroup="kml:SchemaDataExtension"/>
</schema>
"""


class _Offline(etree.Resolver):
    """ogckml22.xsd imports xAL by its OASIS URL: the bundled copy, never the network."""

    def resolve(self, url, pubid, context):
        if url.endswith("/xAL.xsd"):
            return self.resolve_filename(str(XSD / "xAL.xsd"), context)
        return None


@pytest.fixture(scope="module")
def schema():
    parser = etree.XMLParser(no_network=True)
    parser.resolvers.add(_Offline())
    doc = etree.fromstring(STAND_INS.encode(), parser, base_url=str(XSD / "stand-ins.xsd"))
    return etree.XMLSchema(etree.ElementTree(doc))


def _local(el) -> str:
    return el.tag.rsplit("}", 1)[-1]


def _check_gx_content(el) -> None:
    """The content of the gx elements dracc writes, in the order of Google's KML
    reference (gx:MultiTrack: altitudeMode?, gx:interpolate?, gx:Track*; gx:Track:
    altitudeMode?, when*, gx:coord*, gx:angles*, Model?, ExtendedData?), a value per point."""
    kids = [c.tag for c in el]
    if el.tag == GX + "MultiTrack":
        order = [KML + "altitudeMode", GX + "interpolate", GX + "Track"]
        assert el.findtext(GX + "interpolate") in (None, "0", "1")
    elif el.tag == GX + "Track":
        order = [
            KML + "altitudeMode",
            KML + "when",
            GX + "coord",
            GX + "angles",
            KML + "Model",
            KML + "ExtendedData",
        ]
        n = kids.count(KML + "when")
        assert n == kids.count(GX + "coord") > 0
        for c in el.findall(GX + "coord"):
            lon, lat, alt = (float(v) for v in c.text.split(" "))
            assert -180 <= lon <= 180 and -90 <= lat <= 90 and alt == 0
        for arr in el.iterfind(f"{KML}ExtendedData/{KML}SchemaData/{GX}SimpleArrayData"):
            assert len(arr.findall(GX + "value")) == n, arr.get("name")
    elif el.tag == GX + "SimpleArrayField":
        order = [KML + "displayName"]
        assert el.get("name") and el.get("type") == "float"
    elif el.tag == GX + "SimpleArrayData":
        order = [GX + "value"]
        assert el.get("name")
    else:
        pytest.fail(f"a gx element this test does not know: {el.tag}")
    assert set(kids) <= set(order), (el.tag, set(kids) - set(order))
    assert [order.index(t) for t in kids] == sorted(order.index(t) for t in kids), el.tag
    for c in el.iterfind(f"{GX}Track"):
        _check_gx_content(c)
    for c in el.iterfind(f"{KML}ExtendedData/{KML}SchemaData/{GX}SimpleArrayData"):
        _check_gx_content(c)


def _outermost_gx(root) -> list:
    return [
        el
        for el in root.iter(GX + "*")
        if not any(a.tag.startswith(GX) for a in el.iterancestors())
    ]


def assert_valid_kml(schema, data: bytes) -> dict[str, int]:
    """Validate ``data`` as described in the module docstring; return how many of each
    outermost gx element stood in a slot (so a test can say what it covered)."""
    root = etree.fromstring(data, etree.XMLParser(no_network=True, huge_tree=True))
    assert root.tag == KML + "kml"
    counts: dict[str, int] = {}
    for el in _outermost_gx(root):
        name = _local(el)
        assert name in GX_SLOTS, f"gx:{name} has no known OGC extension slot"
        _check_gx_content(el)
        stand_in = etree.Element(f"{{{SLOT}}}{GX_SLOTS[name]}")
        stand_in.tail = el.tail
        el.getparent().replace(el, stand_in)
        counts[name] = counts.get(name, 0) + 1
    assert next(root.iter(GX + "*"), None) is None
    if not schema.validate(root):
        errors = {f"line {e.line}: {e.message}" for e in list(schema.error_log)[:20]}
        pytest.fail("the KML fails the OGC KML 2.2 schema:\n" + "\n".join(sorted(errors)))
    return counts


def _analyze_kml(log: Path, kml: Path, *extra: str):
    """``dracc analyze LOG --kml F``, in process; the file and the Analysis it was made of."""
    from dracc.cli.main import main
    from dracc.pipeline import analysis

    caught = {}
    real = analysis.analyse

    def keep(*args, **kwargs):
        caught["a"] = real(*args, **kwargs)
        return caught["a"]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(analysis, "analyse", keep)
        code = main(["analyze", str(log), "--kml", str(kml), *extra])
    assert code == ExitCode.OK
    return types.SimpleNamespace(data=kml.read_bytes(), analysis=caught["a"])


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    out = tmp_path_factory.mktemp("kml")
    return _analyze_kml(SAMPLES / "voyage_tag.nmea", out / "tag.kml")


def test_the_sample_voyage_kml_validates(schema, sample):
    counts = assert_valid_kml(schema, sample.data)
    # every track as a gx:MultiTrack (DR, EP, reference, the aided EP), the arrays' schema
    assert counts == {"MultiTrack": 4, "SimpleArrayField": 3}, counts


def test_every_shape_of_the_kml_validates(schema, sample):
    """The branches of the writer: no aided EP, no DR (the reference alone), no track at
    all, and a source name full of markup and control characters."""
    from dracc.report.exports import kml_document

    a = sample.analysis
    gnss = next(t for t in a.tracks if t.role == "gnss")
    evil = "GNSS\x1b]0;x\x07</name><x>&amp;]]>"
    shapes = {
        "no aided EP": replace(a, estimated_position=None),
        "no DR": replace(a, dead_reckoning=None),
        "nothing": replace(a, dead_reckoning=None, tracks=()),
        "hostile name": replace(a, tracks=(replace(gnss, source=evil),)),
    }
    for what, variant in shapes.items():
        counts = assert_valid_kml(schema, kml_document(variant))
        assert (
            counts.get("MultiTrack", 0)
            == {
                "no aided EP": 3,
                "no DR": 1,
                "nothing": 0,
                "hostile name": 4,
            }[what]
        ), (what, counts)


def test_a_simulated_voyage_with_misses_validates(schema, run_cli, tmp_path):
    """A GNSS jump puts the reference outside 2M: the misses folder (timed points) too."""
    code, _, err = run_cli(
        "simulate", "--hours", "2", "--seed", "5", "--out", tmp_path,
        "--fault", "jump:GNSS@1h=670m", *SPARSE_RATES,
    )  # fmt: skip
    assert code == ExitCode.OK, err
    run = _analyze_kml(tmp_path / "voyage.nmea", tmp_path / "sim.kml")
    root = etree.fromstring(run.data)
    assert root.findall(f".//{KML}Placemark/{KML}Point"), "no 2M miss in the simulated voyage"
    assert assert_valid_kml(schema, run.data)["MultiTrack"] == 4


def test_a_misplaced_gx_element_or_a_wrong_order_fails(schema, sample):
    """The check can fail: a gx:Track outside a geometry slot, and a Style after the
    Schema (the writer's order before issue 32)."""
    root = etree.fromstring(sample.data)
    doc = root.find(KML + "Document")
    track = next(root.iter(GX + "Track"))
    doc.append(copy.deepcopy(track))  # after the folders: no extension slot there
    with pytest.raises(pytest.fail.Exception, match=r"fails the OGC KML 2\.2 schema"):
        assert_valid_kml(schema, etree.tostring(root))
    root = etree.fromstring(sample.data)
    doc = root.find(KML + "Document")
    doc.find(KML + "Schema").addnext(doc.find(KML + "Style"))
    with pytest.raises(pytest.fail.Exception, match="Style': This element is not expected"):
        assert_valid_kml(schema, etree.tostring(root))
