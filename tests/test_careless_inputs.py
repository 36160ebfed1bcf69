"""Careless inputs a lab produces, beyond those the assumption tests pin down: each ends in a correct result
or a clear irdic error whose message names the file, line, key or store and what was expected."""

import copy
import re

import numpy as np
import pytest
import yaml

from irdic.cli import main
from irdic.config import load_config, load_yaml, validate_config
from irdic.errors import IrdicError

from .test_assumptions import _calibration, _dic, _ir, _nodemaps, _points
from .test_config import ROOT

BASE = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())


def _config(edit):
    c = copy.deepcopy(BASE)
    edit(c)
    validate_config(c)


def _cli(capsys, *argv):
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    assert code == 2 and "internal error" not in err and "Traceback" not in err, err
    raise IrdicError(err.strip())


def _write(path, text, encoding="utf-8"):
    path.write_bytes(text.encode(encoding))
    return path


def _irbis_cut(tmp):
    from irdic.io import read_ir
    from irdic.synthetic.writers import write_irbis

    write_irbis(tmp / "one.txt", np.full((6, 8), 20.0), ms=0.0, frame_index=1)
    raw = (tmp / "one.txt").read_bytes()
    (tmp / "cut.txt").write_bytes(raw[:-30])
    read_ir(tmp / "cut.txt")


def _npy(tmp, name, array, **kw):
    from irdic.io import read_ir

    np.save(tmp / name, array)
    read_ir(tmp / name, **kw)


def _two_sizes(tmp, capsys):
    (tmp / "mix").mkdir()
    np.save(tmp / "mix" / "f_0.npy", np.full((4, 5), 20.0))
    np.save(tmp / "mix" / "f_1.npy", np.full((5, 5), 20.0))
    _cli(capsys, "ingest-ir", tmp / "mix", tmp / "m.zarr", "--frame-rate", "2")


def _empty_stage(tmp, capsys):
    src = _nodemaps(tmp / "dic")
    (src / "spec_0_2.txt").write_text("")
    _cli(capsys, "ingest-dic", src, tmp / "dic.zarr")


def _inch_stage(tmp):
    from irdic.ingest.dic import check_scale

    x = np.random.default_rng(0).uniform(0, 50, (3, 30, 3))
    x[1] /= 25.4
    check_scale(x, ["s_0.csv", "s_1.csv", "s_2.csv"])


def _symlinked_results(tmp):
    (tmp / "raw").mkdir()
    (tmp / "link").symlink_to(tmp / "raw")

    def edit(c):
        c["demo"]["enabled"] = False
        c["experiments"]["tube"]["ir"]["path"] = str(tmp / "raw")
        c["results"] = str(tmp / "link" / "results")
    _config(edit)


# (what a lab did, how to do it, the message the user sees)
CASES = [
    ("results folder left empty", lambda tmp, cap: _config(lambda c: c.update(results="")),
     r"results: '' should be non-empty"),
    ("setup named with another case", lambda tmp, cap: _config(lambda c: c["experiments"]["tube"].update(setup="Lab")),
     r"experiments\.tube\.setup: setup 'Lab' is not defined; defined setups: lab"),
    ("decimal comma in a number", lambda tmp, cap: _config(lambda c: c["interpolation"].update(c_space="2,5")),
     r"interpolation\.c_space: '2,5' is not of type 'number'"),
    ("frame rate with its unit", lambda tmp, cap: _config(
        lambda c: c["experiments"]["tube"]["ir"].update(frame_rate="50 Hz")),
     r"experiments\.tube\.ir\.frame_rate: '50 Hz' is not of type 'number', 'null'"),
    ("frame rate 0", lambda tmp, cap: _config(lambda c: c["experiments"]["tube"]["ir"].update(frame_rate=0)),
     r"experiments\.tube\.ir\.frame_rate: 0 is less than or equal to the minimum of 0"),
    ("yes written for a time offset", lambda tmp, cap: _config(
        lambda c: c["experiments"]["tube"]["ir"].update(time_offset=True)),
     r"experiments\.tube\.ir\.time_offset: True is not a number or 'auto'"),
    ("a key twice inside one section", lambda tmp, cap: load_config(_write(
        tmp / "c.yaml", (ROOT / "config" / "config.yaml").read_text().replace(
            "  c_time: 1.0           # IMQ", "  c_time: 2.0\n  c_time: 1.0           # IMQ"))),
     r"c\.yaml, line \d+: key 'c_time' is given twice in the same mapping \(first at line \d+\)"),
    ("marker IDs 1 and 1.0 in the seeds", lambda tmp, cap: load_yaml(_write(
        tmp / "s.yaml", "seeds: {1: [1, 2], 2: [3, 4], 3: [5, 6], 4: [7, 8], 5: [9, 10], 1.0: [1, 2]}\n")),
     r"s\.yaml, line 1: key 1\.0 is given twice in the same mapping \(first at line 1\)"),
    ("tab indentation in the YAML", lambda tmp, cap: load_config(_write(tmp / "t.yaml", "setups:\n\tlab: {}\n")),
     r"t\.yaml: not valid YAML .*found character '\\t' that cannot start any token"),
    ("config saved in Latin-1", lambda tmp, cap: load_config(_write(tmp / "l.yaml", "# Prüfung\nsetups: {}\n",
                                                                     "latin-1")),
     r"l\.yaml: not a UTF-8 text file \(byte 4 cannot be decoded\)"),
    ("machine record with ',' as separator and decimal mark", lambda tmp, cap: _config(
        lambda c: c["experiments"]["tube"]["machine"].update(sep=",", decimal=",")),
     r"experiments\.tube\.machine\.decimal: ',' is impossible with sep ','"),
    ("results folder is the IR export folder", lambda tmp, cap: _config(
        lambda c: (c["demo"].update(enabled=False), c.update(results="resources/demo/tube/ir"))),
     r"experiments\.tube\.ir\.path: the input resources/demo/tube/ir .* lies inside the results folder"),
    ("results folder reached through a link into the raw data", lambda tmp, cap: _symlinked_results(tmp),
     r"experiments\.tube\.ir\.path: the input .*raw .* contains the results folder .*link/results"),
    ("NaN frame rate on the command line", lambda tmp, cap: _cli(
        cap, "ingest-ir", tmp, tmp / "a.zarr", "--frame-rate", "nan"),
     r"irdic: error: ir\.frame_rate: nan is not a finite number"),
    ("--set with an infinite smoothing", lambda tmp, cap: _cli(
        cap, "run", "--config", ROOT / "config" / "config.yaml", "--set", "fields.c_time=.inf"),
     r"config\.yaml with --set: fields\.c_time: inf is not a finite number"),
    ("IR folder holding only notes and pictures", lambda tmp, cap: (
        (tmp / "ir").mkdir(), _write(tmp / "ir" / "README.md", "x"),
        _cli(cap, "ingest-ir", tmp / "ir", tmp / "ir.zarr")),
     r"irdic: error: .*: folder contains no IR exports"),
    ("IRBIS export cut short by a copy", lambda tmp, cap: _irbis_cut(tmp),
     r"cut\.txt, line 18: data row 6 has \d+ values, expected ImageWidth=8 \(line 3\) \(file truncated\?\)"),
    ("raw detector counts saved as integers", lambda tmp, cap: _npy(tmp, "c.npy", np.full((4, 5), 3000, np.int16)),
     r"c\.npy: holds integers \(int16\); these are usually raw detector counts, not temperatures"),
    ("temperatures in the wrong unit (below absolute zero)", lambda tmp, cap: _npy(tmp, "k.npy",
                                                                                    np.full((4, 5), -300.0)),
     r"k\.npy: temperature -300\.00 °C is below absolute zero; the unit is probably wrong"),
    ("a stack saved with an extra axis", lambda tmp, cap: _npy(tmp, "s.npy", np.zeros((2, 3, 4, 5))),
     r"s\.npy: holds a 4-D array of shape \(2, 3, 4, 5\); expected one frame"),
    ("frames of two sizes in one folder", lambda tmp, cap: _two_sizes(tmp, cap),
     r"f_1\.npy: frame covers u 0\.\.4, v 0\.\.4 \(shape \(5, 5\)\), but the first frame \(f_0\.npy\)"),
    ("an empty DIC stage file", lambda tmp, cap: _empty_stage(tmp, cap), r"spec_0_2\.txt: file is empty"),
    ("one DIC stage exported in inch", lambda tmp, cap: _inch_stage(tmp),
     r"s_1\.csv: its point cloud is 0\.0[34]\d* times the size of the other stages'"),
    ("irdic info on a plain folder", lambda tmp, cap: _cli(cap, "info", tmp),
     r"not a readable zarr store \(no group metadata zarr\.json\)"),
    ("calibration path pointing at points.zarr", lambda tmp, cap: _cli(
        cap, "couple", "--dic", _dic(tmp / "dic.zarr"), "--ir", _ir(tmp / "ir.zarr"), "--calibration",
        _points(tmp / "points.zarr", tmp / "dic.zarr"), "--out", tmp / "p2.zarr"),
     r"points\.zarr: holds point temperatures \(points\.zarr\), written by stage couple; expected a calibration"),
    ("fields given dic.zarr as its points", lambda tmp, cap: _cli(
        cap, "fields", "--points", _dic(tmp / "dic.zarr"), "--calibration", _calibration(tmp / "cal.zarr"),
        "--out", tmp / "f.zarr"),
     r"dic\.zarr: holds DIC points \(dic\.zarr\), written by stage ingest-dic; expected point temperatures"),
    ("frame times that run backwards", lambda tmp, cap: __import__("irdic.ingest.inputs").ingest.inputs.frame_times(
        [0.0, 1.0, 0.5], None, labels=["a.txt", "b.txt", "c.txt"], what="IR frame"),
     r"IR frame times must increase: c\.txt \(t = 0\.5 s\) does not come after b\.txt \(t = 1 s\)"),
]


@pytest.mark.parametrize("what, act, message", CASES, ids=[c[0] for c in CASES])
def test_careless_input_ends_in_a_clear_error(tmp_path, capsys, what, act, message):
    with pytest.raises(IrdicError) as info:
        act(tmp_path, capsys)
    assert re.search(message, str(info.value), re.S), str(info.value)


def test_numbered_series_read_by_frame_rate_with_a_frame_missing_is_timed_right(tmp_path):
    from irdic.ingest.ir import ingest_ir
    from irdic.store import open_store

    for k in (3, 4, 5, 7, 8):  # the export started at frame 3, and frame 6 was not saved
        np.save(tmp_path / f"img{k}.npy", np.full((4, 5), 20.0 + k))
    ds = open_store(ingest_ir(tmp_path, tmp_path / "out" / "ir.zarr", time_source="frame_rate", frame_rate=4.0))
    np.testing.assert_allclose(ds["time"], [0.0, 0.25, 0.5, 1.0, 1.25])
    np.testing.assert_allclose(ds["temperature"].values[:, 0, 0], [23, 24, 25, 27, 28])
