"""Tests of hystcli.io.importer on a committed real excerpt (tests/data/mrdlab) and on small synthetic logs.

Reference values are read by hand from the raw rows of the excerpt (quoted in the comments) and
converted with the scales of sample_data/real/PROVENANCE.md: input = counts * 360/8192 deg,
jaw = counts * 360/4000 deg, current in A as logged.
"""
from __future__ import annotations

import dataclasses
import gzip
import json
import math
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hystcli.io import importer
from hystcli.errors import DataError
from hystcli.io.importer import ColumnMap, ImportMapping, ImportOptions
from hystcli.io import format_run, parse_run

DATA = Path(__file__).parent / "data" / "mrdlab"
LOAD41 = DATA / "load_freq" / "41_first6000.TXT.gz"
PITCH3 = DATA / "pitch_3" / "010_first1000.TXT.gz"
MRD = importer.get_preset("mrdlab")


@pytest.fixture(scope="module")
def load41():
    return importer.convert(LOAD41, MRD)


# --------------------------------------------------------------------------------------------
# the real excerpt through the preset
# --------------------------------------------------------------------------------------------
def test_preset_columns_and_units_by_hand(load41):
    run, rep = load41.run, load41.report
    assert list(run.columns) == ["t", "q1", "y1", "c1"]
    assert len(run) == 6000 and rep.rows_read == 6000 and rep.rows_dropped == 0
    # raw line 10 (first data row): "0.000,0.00,-874.00,-0.045,880.00,..."
    #   t = 0.000 s; q1 = 0 * 360/8192 = 0; y1 = -(880 * 360/4000) = -79.2 (flipped);
    #   c1 = -0.045 A = -45 mA (a run's current is in mA)
    assert run["t"][0] == 0.0 and run["q1"][0] == 0.0
    assert run["y1"][0] == pytest.approx(-79.2, abs=1e-12)
    assert run["c1"][0] == pytest.approx(-45.0, abs=1e-12)
    # raw line 2000 (data row index 1990): "1.990,63.00,1972.00,0.121,817.00,..."
    #   t = 1.990 s (seconds despite the [ms] label); q1 = 63 * 360/8192 = 2.7685546875 deg;
    #   y1 = -(817 * 0.09) = -73.53 deg; c1 = 0.121 A = 121 mA
    assert run["t"][1990] == pytest.approx(1.990, abs=1e-12)
    assert run["q1"][1990] == 2.7685546875
    assert run["y1"][1990] == pytest.approx(-73.53, abs=1e-12)
    assert run["c1"][1990] == pytest.approx(121.0, abs=1e-12)
    # last raw row "5.999,60.00,..." -> 6 s at 1 kHz
    assert run["t"][-1] == pytest.approx(5.999, abs=1e-12)
    assert rep.rate_in == pytest.approx(1000.0, rel=1e-9)
    assert rep.duration == pytest.approx(5.999, abs=1e-9)


def test_preset_metadata_from_header(load41):
    meta = load41.run.meta
    # header line 2: "...tool number 5 Lot M10110805 915 with a 0.50 Hz Sine wave ... amplitude of
    # 30.00 degrees, and a reaction torque of 20.00 percent torque"
    assert meta["tool"] == "5"
    assert meta["catheter"] == "endowrist-tool5"
    assert meta["frequency_hz"] == "0.50"
    assert meta["amplitude_deg"] == "30.00"
    assert meta["load_pct"] == "20.00"
    # the load is the run's condition, the driver of the condition effects (docs/design.md section 8)
    assert meta["condition"] == "20.00"
    assert meta["spindle"] == "left"
    assert meta["motion"] == "periodic"
    assert meta["current_unit"] == "mA"  # the log's A, converted (the import line says so)
    assert "current in A converted to mA (x1000)" in meta["import"]
    assert "output flipped" in meta["import"] and "zero none" in meta["import"]
    # no ReadME beside the load_freq excerpt: no pitch, and no warning about it
    assert "pitch_deg" not in meta
    assert not load41.report.warnings


def test_preset_pitch_from_readme():
    imp = importer.convert(PITCH3, MRD)
    # pitch_3/ReadME.txt: "This is a roll of 0 degrees ... This is a pitch of 0 degrees"
    assert imp.run.meta["pitch_deg"] == "0"
    assert imp.run.meta["roll_deg"] == "0"
    # its header: tool number 4, 0.50 Hz, 20.00 percent
    assert imp.run.meta["catheter"] == "endowrist-tool4"
    assert imp.run.meta["frequency_hz"] == "0.50"
    assert len(imp.run) == 1000


def test_gain_sign_detected_and_flipped(load41):
    k = load41.report.knobs[0]
    # the jaw encoder counts against the spindle: y/q slope about -0.89 on every file of the data set
    # (PROVENANCE: output follows input with a loop of a few degrees, i.e. |gain| near 1)
    assert -1.0 < k.gain < -0.8
    assert k.flipped
    # after the flip the output rises with the input
    q, y = load41.run["q1"], load41.run["y1"]
    assert np.polyfit(q, y, 1)[0] > 0.8


def test_unflipped_negative_gain_is_warned():
    imp = importer.convert(LOAD41, MRD, ImportOptions(flip_output=False))
    assert imp.run["y1"][0] == pytest.approx(79.2, abs=1e-12)  # 880 * 0.09, as read
    assert any("falls as the input rises" in w and "--flip-output" in w for w in imp.report.warnings)


def test_gzip_read_transparently(tmp_path, load41):
    plain = tmp_path / "41.TXT"
    plain.write_bytes(gzip.decompress(LOAD41.read_bytes()))
    imp = importer.convert(plain, MRD)
    for name in load41.run.columns:
        np.testing.assert_array_equal(imp.run[name], load41.run[name])
    # gzip is recognised by content, not by the name
    renamed = tmp_path / "41.dat"
    renamed.write_bytes(LOAD41.read_bytes())
    np.testing.assert_array_equal(importer.convert(renamed, MRD).run["y1"], load41.run["y1"])


def test_zero_first_and_mean(load41):
    first = importer.convert(LOAD41, MRD, ImportOptions(zero="first")).run
    # first sample: q 0 -> 0, y -79.2 -> 0; row 1990 by hand: q 2.7685546875 - 0,
    # y -73.53 - (-79.2) = 5.67
    assert first["q1"][0] == 0.0 and first["y1"][0] == 0.0
    assert first["q1"][1990] == pytest.approx(2.7685546875, abs=1e-12)
    assert first["y1"][1990] == pytest.approx(5.67, abs=1e-9)
    mean = importer.convert(LOAD41, MRD, ImportOptions(zero="mean"))
    assert abs(mean.run["q1"].mean()) < 1e-9 and abs(mean.run["y1"].mean()) < 1e-9
    # zeroing only shifts: differences between samples are those of the raw rows
    assert mean.run["y1"][1990] - mean.run["y1"][0] == pytest.approx(5.67, abs=1e-9)
    # the current is never zeroed, and the report says what was subtracted
    np.testing.assert_array_equal(mean.run["c1"], load41.run["c1"])
    z = mean.report.knobs[0].zero
    assert set(z) == {"q1", "y1"}
    assert z["y1"] == pytest.approx(load41.run["y1"].mean(), abs=1e-9)
    assert load41.report.knobs[0].zero == {}  # default "none"


def test_resample_real_excerpt_to_200hz(load41):
    imp = importer.convert(LOAD41, MRD, ImportOptions(resample=200.0))
    t = imp.run["t"]
    # 0 .. 5.999 s at 200 Hz: 0, 0.005, ..., 5.995 -> 1200 samples
    assert len(t) == 1200
    assert np.allclose(np.diff(t), 0.005)
    assert imp.report.anti_aliased and imp.report.rate_out == pytest.approx(200.0)
    # the 0.5 Hz motion survives the 80 Hz anti-alias filter: within an encoder count of the raw
    # angle at the same instants (1 count = 360/4000 = 0.09 deg)
    raw = load41.run
    assert np.max(np.abs(imp.run["y1"] - raw["y1"][::5])) < 0.09


# --------------------------------------------------------------------------------------------
# synthetic logs: conditioning
# --------------------------------------------------------------------------------------------
def _log(rows, header=("% a header line",)):
    return "\n".join(list(header) + [",".join(repr(float(v)) for v in r) for r in rows]) + "\n"


SIMPLE = ImportMapping(columns=(ColumnMap("t", 1), ColumnMap("q1", 2), ColumnMap("y1", 3)), comment="%")


def test_non_increasing_time_is_an_error_naming_the_line():
    text = _log([(0.0, 1, 1), (0.1, 2, 2), (0.1, 3, 3), (0.3, 4, 4)])
    with pytest.raises(DataError, match=r"line 4 .*time-repair"):
        importer.convert_text(text, SIMPLE, source="x.txt")


def test_time_repair_drop_keeps_first_of_duplicates():
    text = _log([(0.0, 1, 1), (0.1, 2, 2), (0.1, 3, 3), (0.05, 9, 9), (0.3, 4, 4)])
    imp = importer.convert_text(text, SIMPLE, ImportOptions(time_repair="drop"))
    np.testing.assert_array_equal(imp.run["t"], [0.0, 0.1, 0.3])
    np.testing.assert_array_equal(imp.run["q1"], [1, 2, 4])
    assert imp.report.rows_dropped == 2
    assert "2 non-increasing time rows dropped" in imp.run.meta["import"]


def test_time_starts_at_zero_and_rate_without_time_column():
    text = _log([(1000.0, 1, 1), (1000.5, 2, 2), (1001.0, 3, 3)])
    imp = importer.convert_text(text, SIMPLE)
    np.testing.assert_array_equal(imp.run["t"], [0.0, 0.5, 1.0])
    assert imp.report.t_start == 1000.0
    m = ImportMapping(columns=(ColumnMap("q1", 2),), comment="%", rate=4.0)
    np.testing.assert_array_equal(importer.convert_text(text, m).run["t"], [0.0, 0.25, 0.5])


def test_drift_reported_and_detrend_removes_it():
    t = np.arange(0, 20, 0.01)
    q = 30 * np.sin(2 * np.pi * 0.5 * t)
    y = 0.9 * q + 0.1 * t + 5.0  # drift 0.1 deg/s by construction
    text = _log(zip(t, q, y))
    kept = importer.convert_text(text, SIMPLE)
    assert kept.report.knobs[0].drift == pytest.approx(0.1, abs=1e-9)
    assert kept.report.knobs[0].gain == pytest.approx(0.9, abs=1e-9)
    np.testing.assert_allclose(kept.run["y1"], y, atol=1e-9)  # reported, not removed
    gone = importer.convert_text(text, SIMPLE, ImportOptions(detrend=True))
    # y - 0.1 t: what is left is 0.9 q + 5
    np.testing.assert_allclose(gone.run["y1"], 0.9 * q + 5.0, atol=1e-9)
    assert gone.report.knobs[0].detrended


def test_anti_alias_removes_noise_above_new_nyquist():
    t = np.arange(0, 4, 0.001)
    q = 10 * np.sin(2 * np.pi * 0.5 * t)
    c = np.sin(2 * np.pi * 310 * t)  # 310 Hz would fold to 110 Hz -> 90 Hz at 200 Hz sampling
    m = ImportMapping(columns=(ColumnMap("t", 1), ColumnMap("q1", 2), ColumnMap("c1", 3)), comment="%")
    imp = importer.convert_text(_log(zip(t, q, c)), m, ImportOptions(resample=200.0))
    inner = imp.run["c1"][20:-20]
    # 3rd-order Butterworth at 80 Hz, forward-backward: |H(310)|^2 = 1/(1+(310/80)^6) ~ 3e-4
    assert np.max(np.abs(inner)) < 0.01
    # and the slow input is untouched (|H(0.5)| = 1 within 1e-12)
    np.testing.assert_allclose(imp.run["q1"][20:-20], 10 * np.sin(2 * np.pi * 0.5 * imp.run["t"][20:-20]),
                               atol=1e-3)


def test_upsampling_interpolates_linearly():
    text = _log([(0.0, 0.0, 0.0), (1.0, 10.0, 5.0)])
    imp = importer.convert_text(text, SIMPLE, ImportOptions(resample=4.0))
    np.testing.assert_allclose(imp.run["t"], [0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(imp.run["q1"], [0, 2.5, 5, 7.5, 10])
    assert not imp.report.anti_aliased


def test_meta_templates_and_precedence():
    m = ImportMapping(columns=SIMPLE.columns, comment="%",
                      meta={"catheter": "rig-{unit}", "motion": "sweep"},
                      meta_from_header=(importer.parse_meta_pattern(r"unit=unit=(\w+)"),
                                        importer.parse_meta_pattern(r"speed (?P<speed>\d+) (?P<units>\w+)")))
    text = _log([(0, 1, 1), (1, 2, 2)], header=("% rig unit=B7", "% speed 40 dps"))
    imp = importer.convert_text(text, m, ImportOptions(meta={"motion": "periodic"}))
    assert imp.run.meta["catheter"] == "rig-B7"
    assert imp.run.meta["unit"] == "B7"
    assert imp.run.meta["speed"] == "40" and imp.run.meta["units"] == "dps"
    assert imp.run.meta["motion"] == "periodic"  # options win over the mapping
    # a mapping's template naming a key nothing found: warned, key left out; in options: an error
    loose = ImportMapping(columns=SIMPLE.columns, comment="%", meta={"catheter": "rig-{serial}"})
    imp = importer.convert_text(text, loose)
    assert "catheter" not in imp.run.meta
    assert any("{serial}" in w for w in imp.report.warnings)
    with pytest.raises(DataError, match=r"\{serial\}"):
        importer.convert_text(text, SIMPLE, ImportOptions(meta={"catheter": "rig-{serial}"}))


def test_unmatched_header_pattern_is_a_warning():
    m = ImportMapping(columns=SIMPLE.columns, comment="%",
                      meta_from_header=(importer.parse_meta_pattern("freq=([0-9.]+) Hz"),))
    imp = importer.convert_text(_log([(0, 1, 1), (1, 2, 2)]), m)
    assert "freq" not in imp.run.meta
    assert any("matched no header line" in w for w in imp.report.warnings)


def test_output_reads_back_as_a_run(load41):
    back = parse_run(format_run(load41.run), require=("q1", "y1", "c1"))
    np.testing.assert_array_equal(back["y1"], load41.run["y1"])
    assert back.meta["catheter"] == "endowrist-tool5"


def test_decimals_round_values():
    text = _log([(0.0, 1.23456789, 0), (0.1, 2.0, 0)])
    imp = importer.convert_text(text, SIMPLE, ImportOptions(decimals=3))
    assert imp.run["q1"][0] == 1.235
    with pytest.raises(DataError, match="decimals are too few"):
        importer.convert_text(_log([(0.0, 1, 0), (0.0001, 2, 0)]), SIMPLE, ImportOptions(decimals=3))


# --------------------------------------------------------------------------------------------
# mappings and their errors
# --------------------------------------------------------------------------------------------
def test_map_spec_parsing():
    cols = importer.parse_map_spec("t=1:0.001,q1=2:360/8192,y1=5:0.09:-12.5,c1=4")
    assert cols[0] == ColumnMap("t", 1, 0.001, 0.0)
    assert cols[1].scale == 0.0439453125  # 360/8192 exactly
    assert cols[2] == ColumnMap("y1", 5, 0.09, -12.5)
    assert cols[3] == ColumnMap("c1", 4, 1.0, 0.0)


@pytest.mark.parametrize("spec, message", [
    ("z1=2", "unknown target column 'z1'"),
    ("q1=0", "columns count from 1"),
    ("q1=", "expected target=column"),
    ("q1=knob:parsec", "'parsec' is not a number or an angle unit"),
    ("c1=I:rad", "'rad' is not a number or a current unit"),
    ("q1=2:abc", "'abc' is not a number"),
    ("q1=2:0", "scale 0"),
    ("q1=2:inf", "not a finite number"),
    ("q1=2:1/0", "not a number"),
    ("q1", "expected target=column"),
    ("q1=2,q1=3", "mapped twice"),
])
def test_bad_map_specs(spec, message):
    with pytest.raises(DataError, match=message):
        ImportMapping(columns=(ColumnMap("t", 1),) + importer.parse_map_spec(spec))


def test_mapping_needs_time_or_rate():
    with pytest.raises(DataError, match="no time column"):
        ImportMapping(columns=(ColumnMap("q1", 2),))


def test_column_out_of_range_names_line():
    m = ImportMapping(columns=(ColumnMap("t", 1), ColumnMap("q1", 11)), comment="%")
    with pytest.raises(DataError, match=r"line 10 has 10 fields, the mapping reads column 11"):
        importer.convert(LOAD41, m)


def test_non_numeric_cell_names_line_and_column(tmp_path):
    p = tmp_path / "log.csv"
    p.write_text("time,angle,tip\n0,1,2\n0.1,x,3\n")
    m = ImportMapping(columns=(ColumnMap("t", 1), ColumnMap("q1", 2)), comment="%", skip=1)
    with pytest.raises(DataError, match=r"line 3, column 2 \(q1\): 'x' is not a number"):
        importer.convert(p, m)
    # a names row not skipped: the hint says how
    with pytest.raises(DataError, match=r"line 1, .*--skip"):
        importer.convert(p, ImportMapping(columns=m.columns, comment="%"))
    p.write_text("0,1\n0.1,nan\n")
    with pytest.raises(DataError, match="not a finite number"):
        importer.convert(p, ImportMapping(columns=m.columns))


@pytest.mark.parametrize("content, message", [
    (b"", "empty file"),
    (b"   \n\n", "empty file"),
    (b"% only a header\n", "no data rows"),
    (b"\x1f\x8b\x08\x00garbage", "corrupt gzip"),
    (b"\x00\x01\x02\x03", "binary"),
])
def test_unreadable_files(tmp_path, content, message):
    p = tmp_path / "raw.txt"
    p.write_bytes(content)
    with pytest.raises(DataError, match=message):
        importer.convert(p, MRD)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(DataError, match="no such file"):
        importer.convert(tmp_path / "nope.txt", MRD)
    with pytest.raises(DataError, match="is a directory"):
        importer.convert(tmp_path, MRD)


def test_truncated_gzip_is_corrupt(tmp_path):
    p = tmp_path / "cut.TXT.gz"
    p.write_bytes(LOAD41.read_bytes()[:5000])
    with pytest.raises(DataError, match="corrupt gzip"):
        importer.convert(p, MRD)


def test_whitespace_and_tab_separators():
    text = "# hdr\n0 1.5  2\n0.5\t3 4\n"
    m = ImportMapping(columns=SIMPLE.columns, separator=None)
    imp = importer.convert_text(text, m)
    np.testing.assert_array_equal(imp.run["q1"], [1.5, 3])
    m2 = ImportMapping(columns=SIMPLE.columns, separator=importer.parse_separator("tab"))
    np.testing.assert_array_equal(importer.convert_text("0\t1\t2\n1\t3\t4\n", m2).run["y1"], [2, 4])


def test_mapping_json_round_trip_and_errors(tmp_path):
    d = importer.mapping_to_dict(MRD)
    p = tmp_path / "m.json"
    p.write_text(json.dumps(d))
    m = importer.load_mapping(p)
    assert m.columns == MRD.columns and m.flip_output and m.comment == "%"
    assert [x.regex for x in m.meta_from_header] == [x.regex for x in MRD.meta_from_header]
    np.testing.assert_array_equal(importer.convert(LOAD41, m).run["y1"][:50],
                                  importer.convert(LOAD41, MRD).run["y1"][:50])
    doc = {"columns": {"t": 1, "q1": {"column": 2, "scale": "360/8192"}, "y1": {"column": 5, "scale": 0.09}},
           "comment": "%"}
    p.write_text(json.dumps(doc))
    assert importer.load_mapping(p).column("q1").scale == 360 / 8192
    for bad, msg in [({**doc, "colums": {}}, "unknown key 'colums'"),
                     ({**doc, "format": "other"}, "format"),
                     ({**doc, "version": 2}, "unknown mapping version"),
                     ({"columns": {"t": 1, "w1": 2}}, "unknown target column 'w1'"),
                     ({"columns": {"t": 1, "q1": {"column": 2, "scale": "x"}}}, "'x' is not a number"),
                     ({"columns": {"t": 1, "q1": {"col": 2}}}, "expected a column number")]:
        p.write_text(json.dumps(bad))
        with pytest.raises(DataError, match=msg):
            importer.load_mapping(p)
    p.write_text("{not json")
    with pytest.raises(DataError, match="not valid JSON"):
        importer.load_mapping(p)


def test_unknown_preset():
    with pytest.raises(DataError, match="unknown preset 'nope'.*mrdlab"):
        importer.get_preset("nope")


def test_output_name():
    assert importer.output_name("a/00.TXT.gz") == "00.csv"
    assert importer.output_name("run.log") == "run.csv"
    assert importer.output_name("noext") == "noext.csv"


# --------------------------------------------------------------------------------------------
# properties
# --------------------------------------------------------------------------------------------
finite = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(finite, finite), min_size=2, max_size=30),
       st.floats(-100, 100).filter(lambda s: abs(s) > 1e-6), finite)
def test_scale_and_offset_applied_to_every_cell(rows, scale, offset):
    text = "\n".join(f"{i * 0.01!r},{a!r},{b!r}" for i, (a, b) in enumerate(rows)) + "\n"
    m = ImportMapping(columns=(ColumnMap("t", 1), ColumnMap("q1", 2, scale, offset), ColumnMap("c1", 3)))
    run = importer.convert_text(text, m).run
    np.testing.assert_array_equal(run["q1"], np.array([a for a, _ in rows]) * scale + offset)
    np.testing.assert_array_equal(run["c1"], [b for _, b in rows])


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 50), min_size=2, max_size=40))
def test_time_drop_leaves_strictly_increasing_time(ticks):
    text = "\n".join(f"{t * 0.1!r},{i},0" for i, t in enumerate(ticks)) + "\n"
    # the kept rows are exactly the running records of the raw times
    record, kept = -math.inf, []
    for i, x in enumerate(ticks):
        if x * 0.1 > record:
            kept.append(i)
            record = x * 0.1
    if len(kept) < 2:
        with pytest.raises(DataError, match="a run needs at least 2"):
            importer.convert_text(text, SIMPLE, ImportOptions(time_repair="drop"))
        return
    imp = importer.convert_text(text, SIMPLE, ImportOptions(time_repair="drop"))
    assert np.all(np.diff(imp.run["t"]) > 0)
    np.testing.assert_array_equal(imp.run["q1"], kept)


# --------------------------------------------------------------------------------------------
# a log read by the CSV parser converts as one read line by line
# --------------------------------------------------------------------------------------------
def _both(tmp_path, data: bytes, mapping: ImportMapping):
    """convert() of the file (the CSV parser where it can) and convert_text() of its text (line
    by line): each the Imported or the error message."""
    p = tmp_path / "log.txt"
    p.write_bytes(data)
    out = []
    for conv in (lambda: importer.convert(p, mapping), lambda: importer.convert_text(importer.read_text(p), mapping,
                                                                                       source=str(p))):
        try:
            out.append(conv())
        except DataError as exc:
            out.append(str(exc))
    return out


def _same(a, b):
    if isinstance(b, str):
        assert a == b
        return
    assert not isinstance(a, str), a
    assert dict(a.run.meta) == dict(b.run.meta) and a.report == b.report
    for name in b.run.columns:
        np.testing.assert_array_equal(a.run[name], b.run[name])


COMMA = ImportMapping(columns=(ColumnMap("t", 1, 0.001), ColumnMap("q1", 3, 360 / 8192), ColumnMap("y1", 2, -1.0, 5.0),
                               ColumnMap("r1", 2)), separator=",", comment="%", skip=1)


@pytest.mark.parametrize("mapping, data", [
    (SIMPLE, b"% head\n% more\n0 1 2\n1 2 3\n2 3 4\n"),
    (SIMPLE, b"% head\n\n  0\t1  2 extra\n1 2 3 more\n2 3 4 x\n"),
    (SIMPLE, b"% head\r\n0 1 2\r\n1 2 3\r\n"),
    (SIMPLE, b"% head\n0 1 2\n% a note among the rows\n1 2 3\n"),   # line by line: the note is a header line
    (SIMPLE, b"% head\n0 1 2\n\n1 2 3\n"),
    (SIMPLE, b"% head\n0 1 2\n1 2\n"), (SIMPLE, b"% head\n0 1 2\n1 2 abc\n"), (SIMPLE, b"% head\n0 1 2\n1 2 nan\n"),
    (SIMPLE, b"% head\n0 1 2\n1 2 inf\n"), (SIMPLE, b"% head\n0 1 2\n1 2 3 4 5\n"), (SIMPLE, b"% head\n0 1 2\n0 2 3\n"),
    (SIMPLE, b"% h\xb0\n0 1 2\n1 2 3\n"), (SIMPLE, "% h\u00b0\n0 1 2\n1 2 3\n".encode()), (SIMPLE, b"% head\n0 1 2\n"),
    (SIMPLE, b"% head\n0 1 2\r1 2 3\n"), (SIMPLE, b"% head\n0 1 2\n1 2 3\x0c\n"), (SIMPLE, b"% head\n0 1_0 2\n1 2 3\n"),
    (COMMA, b"time,jaw,x,knob\n0, 1,2,3\n1000 ,2, 3,4\n2000,3,4,5\n"),
    (COMMA, b'time,jaw,x,knob\n0,"1",2,3\n1000,2,3,4\n'), (COMMA, b"time,jaw,x,knob\n0,1,2\n1000,2,3\n"),
    (COMMA, b"\xef\xbb\xbftime,jaw,x,knob\n%c\n0,1,2,3\n1000,2,3,4\n   \n"),
])
def test_the_csv_parser_converts_as_the_line_reader(tmp_path, mapping, data):
    _same(*_both(tmp_path, data, mapping))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(1e-6, 1e3), st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)), min_size=2, max_size=40),
       st.sampled_from([" ", "\t", ","]), st.booleans())
def test_any_plain_log_converts_the_same_by_either_reader(tmp_path_factory, rows, sep, crlf):
    t = np.cumsum([r[0] for r in rows])
    nl = "\r\n" if crlf else "\n"
    text = f"% a header{nl}" + "".join(f"{a!r}{sep}{r[1]!r}{sep}{r[2]!r}{nl}" for a, r in zip(t.tolist(), rows))
    mapping = dataclasses.replace(SIMPLE, separator=None if sep == " " else sep)
    p = tmp_path_factory.mktemp("log") / "log.txt"
    p.write_text(text, newline="")
    with mock.patch("hystcli.io.importer._parse_table", side_effect=AssertionError("read line by line")):
        fast = importer.convert(p, mapping)   # a plain log goes through the CSV parser only
    _same(fast, importer.convert_text(text, mapping, source=str(p)))


def test_the_real_excerpt_streams_through_the_csv_parser_from_gzip():
    """The committed MRDLab excerpt (gzip, '%' header lines, commas): read on the fly by the CSV
    parser, to the same run and report as the line reader's."""
    with mock.patch("hystcli.io.importer._parse_table", side_effect=AssertionError("read line by line")):
        fast = importer.convert(LOAD41, MRD)
    _same(fast, importer.convert_text(importer.read_text(LOAD41), MRD, source=str(LOAD41)))


@settings(max_examples=60, deadline=None)
@given(st.integers(50, 20_000), st.floats(0.01, 2.0), st.floats(-3, 3), st.floats(-1, 1), st.floats(-100, 100),
       st.integers(0, 2**32 - 1))
def test_gain_and_drift_are_least_squares(n, freq, gain, drift, offset, seed):
    """The 2x2 normal equations give lstsq's gain and drift on a sweep (a knob sine against time),
    and near-collinear knob and time go to lstsq itself."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(1e-3, 2e-3, n))
    for q in (40 * np.sin(2 * np.pi * freq * t) + rng.normal(0, 0.5, n), 3.0 * t + rng.normal(0, 1e-4, n)):
        y = gain * q + drift * t + offset + rng.normal(0, 0.3, n)
        a = np.column_stack([q, np.ones_like(q), t - t[0]])
        want, *_ = np.linalg.lstsq(a, y, rcond=None)
        got_gain, got_drift = importer._gain_drift(q, y, t)
        # each coefficient's difference, as the change of the fitted tip it makes, against the tip
        size = np.linalg.norm(a, axis=0)
        assert abs(got_gain - want[0]) * size[0] <= 1e-10 * np.linalg.norm(y)
        assert abs(got_drift - want[2]) * size[2] <= 1e-10 * np.linalg.norm(y)


# --------------------------------------------------------------------------------------------
# columns by name, units, and what the file's own layout says
# --------------------------------------------------------------------------------------------
USER_TSV = ("# bench log, knob 1\n"
            "time_ms\tknob_rad\ttip_deg\tI_A\n"
            "0\t0.0\t1.5\t0.010\n"
            "10\t0.5\t2.5\t0.020\n"
            "20\t1.0\t3.5\t-0.005\n")


def test_map_spec_takes_names_and_units():
    cols = importer.parse_map_spec("t=time_ms:ms,q1=knob_rad:rad,y1=tip_deg,c1=I_A:A,r1=3:2:0.5")
    assert cols[0] == ColumnMap("t", "time_ms", unit="ms") and cols[0].factor == 1e-3
    assert cols[1].unit == "rad" and cols[1].factor == pytest.approx(180 / math.pi)
    assert cols[2] == ColumnMap("y1", "tip_deg")
    assert cols[3].unit == "A" and cols[3].factor == 1000.0
    assert cols[4] == ColumnMap("r1", 3, 2.0, 0.5)  # a number is still a column number, then scale, offset
    assert importer.parse_map_spec("c1=I:a")[0].unit == "A"  # units ignore case
    assert [c.spec() for c in cols[:2]] == ["t=time_ms:ms", "q1=knob_rad:rad"]
    with pytest.raises(DataError, match="a unit or a scale, not both"):
        ColumnMap("t", 1, 0.5, unit="ms")


def test_names_units_tab_and_comment_lines_are_read_from_the_file():
    m = ImportMapping(columns=importer.parse_map_spec("t=time_ms:ms,q1=knob_rad:rad,y1=tip_deg,c1=I_A:A"),
                      separator=importer.AUTO, comment=importer.AUTO)
    imp = importer.convert_text(USER_TSV, m)
    np.testing.assert_allclose(imp.run["t"], [0.0, 0.01, 0.02])
    np.testing.assert_allclose(imp.run["q1"], [0.0, 28.64788975654116, 57.29577951308232])  # 0.5 rad in deg
    np.testing.assert_allclose(imp.run["c1"], [10.0, 20.0, -5.0])  # A to mA by the mapping's unit
    assert imp.run.meta["current_unit"] == "mA"
    assert not any("current unit" in w for w in imp.report.warnings)  # the unit is stated


@pytest.mark.parametrize("sep", [",", "\t", ";", "   "])
def test_separator_and_header_row_are_sniffed(sep):
    text = "% a comment\n" + "\n".join(sep.join(row) for row in
                                       [["time", "knob", "tip"], ["0", "1.5", "2"], ["0.5", "3", "4"]]) + "\n"
    m = ImportMapping(columns=importer.parse_map_spec("t=time,q1=knob,y1=3"), separator=importer.AUTO,
                      comment=importer.AUTO)
    imp = importer.convert_text(text, m)
    np.testing.assert_array_equal(imp.run["q1"], [1.5, 3.0])
    np.testing.assert_array_equal(imp.run["y1"], [2.0, 4.0])
    layout = importer.split_table(text, importer.AUTO, importer.AUTO, names_row=None)
    assert layout.names == ("time", "knob", "tip") and layout.separator == (None if sep == "   " else sep)


def test_a_header_row_is_found_when_columns_are_numbers_too():
    text = "t,q,y\n0,1,2\n1,3,4\n"
    m = ImportMapping(columns=importer.parse_map_spec("t=1,q1=2"), separator=importer.AUTO)
    np.testing.assert_array_equal(importer.convert_text(text, m).run["q1"], [1.0, 3.0])


def test_a_name_the_file_lacks_names_the_columns_it_has():
    m = ImportMapping(columns=importer.parse_map_spec("t=time_ms:ms,q1=knob"), separator=importer.AUTO,
                      comment=importer.AUTO)
    with pytest.raises(DataError) as err:
        importer.convert_text(USER_TSV, m, source="log.tsv")
    assert str(err.value) == ("log.tsv: no column 'knob' for q1 (the file has time_ms, knob_rad, tip_deg, I_A); "
                              "did you mean 'knob_rad'?")
    m = ImportMapping(columns=importer.parse_map_spec("t=time,q1=2"), separator=importer.AUTO)
    with pytest.raises(DataError, match="no header row to find 'time' in"):
        importer.convert_text("0,1\n1,2\n", m)


def test_columns_mapping_keeps_run_columns_and_metadata_and_time(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text("# shape: alpha=45\n# catheter: mine\nt,q1,tip\n5.0,1,2\n5.5,2,3\n")
    imp = importer.read_mapped(p, importer.columns_mapping("y1=tip"), require=("t", "q1", "y1"))
    assert list(imp.run.columns) == ["t", "q1", "y1"]
    np.testing.assert_array_equal(imp.run["t"], [5.0, 5.5])  # time kept, not shifted to 0
    assert imp.run.meta["shape"] == "alpha=45" and imp.run.meta["catheter"] == "mine"
    with pytest.raises(DataError, match=r"missing column 'c1' \(columns: t, q1, y1\)"):
        importer.read_mapped(p, importer.columns_mapping("y1=tip"), require=("t", "c1"))
    p.write_text("time,q1\n0,1\n1,2\n")
    with pytest.raises(DataError, match=r"no time column: map t=COLUMN \(the file has time, q1\)"):
        importer.read_mapped(p, importer.columns_mapping("y1=2"))


def test_columns_mapping_refuses_what_a_run_refuses(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text("time,knob\n0,1\n1,1e308\n")
    with pytest.raises(DataError, match=r"line 3, column 'knob' \(q1\): '1e308' is beyond"):
        importer.read_mapped(p, importer.columns_mapping("t=time,q1=knob"))
    p.write_text("time,knob\n0,1\n0,2\n")
    with pytest.raises(DataError, match="time repeats at line 3"):
        importer.read_mapped(p, importer.columns_mapping("t=time,q1=knob"))


def test_suggested_columns_come_from_the_names():
    assert importer.suggest_columns(["time_s", "knob_deg", "tip_deg", "current_mA"]) == \
        "t=time_s,q1=knob_deg,y1=tip_deg,c1=current_mA"
    assert importer.suggest_columns(["Time_ms", "knob_rad", "current_A"]) == \
        "t=Time_ms:ms,q1=knob_rad:rad,c1=current_A:A"
    assert importer.suggest_columns(["a", "b"]) is None


def test_mapping_json_takes_names_and_units():
    m = importer.mapping_from_dict({"columns": {"t": {"column": "time_ms", "unit": "ms"}, "q1": "knob"}})
    assert m.column("t") == ColumnMap("t", "time_ms", unit="ms") and m.column("q1").column == "knob"
    assert importer.mapping_from_dict(importer.mapping_to_dict(m)).columns == m.columns
