"""The production line: `triaxcal batch` on simulated boards with known faults."""

from __future__ import annotations

import csv
import json
from collections import Counter

import numpy as np
import pytest
from _boards import FAULTS, WINDOW, make_board, production_run, write_session
from triaxcal import Calibration, PoseSettings
from triaxcal.calibration.request import SourceOptions
from triaxcal.cli import main
from triaxcal.errors import CalibrationError
from triaxcal.fleet.batch import (
    SUMMARY_COLUMNS,
    Limits,
    batch_fit,
    batch_request,
    read_grouped_table,
)


def summary(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_thousand_boards_fifty_bad_every_fault_named(tmp_path, capsys):
    faults = production_run(tmp_path / "sessions", n=1000, n_bad=50)
    assert sum(f is not None for f in faults.values()) == 50
    rc = main(["batch", str(tmp_path / "sessions"), "--out-dir", str(tmp_path / "out"),
               "--window", str(WINDOW), "--jobs", "2"])
    assert rc == 1  # some boards fail
    rows = {r["id"]: r for r in summary(tmp_path / "out" / "summary.csv")}
    assert len(rows) == 1000
    confusion = Counter()
    for bid, fault in faults.items():
        r = rows[bid]
        got = r["reasons"].split("|")[0] if r["verdict"] == "fail" else "pass"
        confusion[(fault or "good", got)] += 1
    print("\ninjected -> verdict (main reason):")
    for (k, v), c in sorted(confusion.items()):
        print(f"  {k:>10} -> {v:<10} {c}")
    good_fail = {k: c for k, c in confusion.items() if k[0] == "good" and k[1] != "pass"}
    assert not good_fail, f"good boards failed: {good_fail}"
    wrong = {k: c for k, c in confusion.items()
             if k[0] != "good" and k[1] != FAULTS[k[0]]}
    assert not wrong, f"bad boards not flagged with their fault: {wrong}"
    assert confusion[("good", "pass")] == 950
    # files: every fitted board has its calibration, only passing ones have headers
    ok = next(b for b, f in faults.items() if f is None)
    assert (tmp_path / "out" / ok / "triaxcal_calibration.h").exists()
    assert (tmp_path / "out" / ok / "triaxcal_calibration_fixed.h").exists()
    off = next(b for b, f in faults.items() if f == "offset")
    cal = Calibration.load(tmp_path / "out" / off / "calibration.json")
    assert cal.extra["verdict"] == "fail" and cal.extra["reasons"][0] == "offset"
    assert not (tmp_path / "out" / off / "triaxcal_calibration.h").exists()
    out = capsys.readouterr().out
    assert "boards: 950 pass, 50 fail" in out


def test_batch_equals_fitting_each_session_alone(tmp_path):
    folder = tmp_path / "s"
    folder.mkdir()
    for i, fault in enumerate([None, None, "offset", "cross_axis"]):
        write_session(folder / f"B{i}.csv", 1.7e9, make_board(40 + i, fault)[0])
    assert main(["batch", str(folder), "--out-dir", str(tmp_path / "out"), "--window",
                 str(WINDOW), "--jobs", "2", "--quiet"]) == 1
    for i in range(4):
        alone = tmp_path / f"alone{i}.json"
        assert main(["fit", str(folder / f"B{i}.csv"), "--poses", "--window", str(WINDOW),
                     "-o", str(alone)]) == 0
        a = Calibration.load(alone).accel
        b = Calibration.load(tmp_path / "out" / f"B{i}" / "calibration.json").accel
        assert a == b  # offsets, matrix, stats, provenance: all identical
    rows = summary(tmp_path / "out" / "summary.csv")
    assert [r["id"] for r in rows] == ["B0", "B1", "B2", "B3"]
    assert [r["verdict"] for r in rows] == ["pass", "pass", "fail", "fail"]
    assert tuple(rows[0]) == SUMMARY_COLUMNS
    b0 = Calibration.load(tmp_path / "out" / "B0" / "calibration.json").accel
    assert float(rows[0]["offset_x"]) == b0.offset[0]
    assert float(rows[0]["diag_z"]) == b0.diag[2]
    assert 0 < float(rows[0]["rms"]) < 0.01 and float(rows[0]["coverage_pct"]) >= 40


def test_one_table_of_many_boards_csv_and_parquet(tmp_path):
    lines = ["device_id,t,ax,ay,az"]
    expected = {}
    for i, fault in enumerate([None, "noise", None]):
        counts = make_board(70 + i, fault)[0]
        bid = f"dev-{i}"
        expected[bid] = fault
        lines += [f"{bid},{k / 50:.2f},{x},{y},{z}" for k, (x, y, z) in
                  enumerate(counts.tolist())]
    table = tmp_path / "fleet.csv"
    table.write_text("\n".join(lines) + "\n")
    rc = main(["batch", str(table), "--by", "device_id", "--out-dir", str(tmp_path / "o1"),
               "--window", str(WINDOW), "--quiet", "--jobs", "1"])
    assert rc == 1
    rows = {r["id"]: r for r in summary(tmp_path / "o1" / "summary.csv")}
    assert rows["dev-0"]["verdict"] == "pass" and rows["dev-2"]["verdict"] == "pass"
    assert rows["dev-1"]["reasons"] == "noise"
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    data = np.genfromtxt(table, delimiter=",", skip_header=1, dtype=None, encoding="ascii")
    cols = {n: [row[k] for row in data] for k, n in enumerate(["device_id", "t", "ax", "ay",
                                                                 "az"])}
    pq.write_table(pa.table(cols), tmp_path / "fleet.parquet")
    rc = main(["batch", str(tmp_path / "fleet.parquet"), "--by", "device_id", "--out-dir",
               str(tmp_path / "o2"), "--window", str(WINDOW), "--quiet", "--jobs", "1"])
    assert rc == 1
    a = Calibration.load(tmp_path / "o1" / "dev-0" / "calibration.json").accel
    b = Calibration.load(tmp_path / "o2" / "dev-0" / "calibration.json").accel
    assert np.array_equal(a.offset, b.offset) and np.array_equal(a.matrix, b.matrix)


def test_limits_are_configurable(tmp_path):
    folder = tmp_path / "s"
    folder.mkdir()
    write_session(folder / "X.csv", 1.7e9, make_board(90, "offset")[0])
    assert main(["batch", str(folder), "--out-dir", str(tmp_path / "a"), "--window", str(WINDOW),
                 "--quiet"]) == 1
    assert main(["batch", str(folder), "--out-dir", str(tmp_path / "b"), "--window", str(WINDOW),
                 "--quiet", "--limit", "offset_max=0.3"]) == 0
    (tmp_path / "lim.json").write_text(json.dumps({"offset_max": 0.3, "noise_max": 0.0001}))
    assert main(["batch", str(folder), "--out-dir", str(tmp_path / "c"), "--window", str(WINDOW),
                 "--quiet", "--limits", str(tmp_path / "lim.json")]) == 1
    assert summary(tmp_path / "c" / "summary.csv")[0]["reasons"] == "noise"
    assert (tmp_path / "b" / "X" / "triaxcal_calibration.h").exists()


def test_hostile_inputs(tmp_path, capsys):
    folder = tmp_path / "s"
    folder.mkdir()
    (folder / "=HYPERLINK(1).csv").write_text("t,ax,ay,az\n1,2,3\n")
    (folder / "empty.csv").write_text("")
    (folder / "words.csv").write_text("t,ax,ay,az\n1,a,b,c\n")
    write_session(folder / "good.csv", 1.7e9, make_board(3)[0])
    rc = main(["batch", str(folder), "--out-dir", str(tmp_path / "o"), "--window", str(WINDOW),
               "--quiet", "--jobs", "1"])
    assert rc == 1
    rows = {r["id"]: r for r in summary(tmp_path / "o" / "summary.csv")}
    assert rows["good"]["verdict"] == "pass"
    assert rows["empty"]["reasons"] == "unreadable" and rows["words"]["reasons"] == "unreadable"
    # the file name became a safe id, and no cell starts a spreadsheet formula
    assert "'=HYPERLINK_1_" in rows or "_HYPERLINK_1_" in rows
    raw = (tmp_path / "o" / "summary.csv").read_text()
    assert "\n=" not in raw and ",=" not in raw
    for bad in (["--limit", "nope=1"], ["--limit", "offset_max=x"], ["--limit", "offset_max=-1"]):
        assert main(["batch", str(folder), "--out-dir", str(tmp_path / "o"), "--quiet", *bad]) == 1
        assert "limit" in capsys.readouterr().err
    assert main(["batch", str(tmp_path / "nothing"), "--out-dir", str(tmp_path / "o")]) == 1
    with pytest.raises(CalibrationError, match="no column"):
        read_grouped_table(folder / "good.csv", "device_id")


def test_library_call_in_process():
    counts = make_board(11)[0]
    from triaxcal.io.tables import Table

    t = Table(names=("ax", "ay", "az"), data=counts.astype(float), path=__import__(
        "pathlib").Path("mem"), sha256="0" * 64)
    req = batch_request(source=SourceOptions(poses=True, detection=PoseSettings(window=WINDOW)))
    res = batch_fit([("a", t)], request=req, limits=Limits(), jobs=1)
    assert res[0].passed and res[0].part is not None and res[0].outputs == ()
    with pytest.raises(CalibrationError):
        Limits(offset_max=float("nan"))


def test_grouped_table_keeps_ids_apart_and_reads_numbers_as_the_table_reader(tmp_path):
    """Ids that differ only by spaces are other boards; a value read_table refuses (nan,
    1_000) is refused here too; a --limits path that is not a regular file is refused."""
    from triaxcal.fleet.batch import load_limits, read_grouped_table

    p = tmp_path / "g.csv"
    p.write_text("id,x,y,z\nB1,1,2,3\nB1 ,4,5,6\n")
    assert [i for i, _ in read_grouped_table(p, "id")] == ["B1", "B1 "]
    for bad in ("nan", "1_000", "inf"):
        p.write_text(f"id,x,y,z\nB1,1,2,{bad}\n")
        with pytest.raises(CalibrationError, match="line 2"):
            read_grouped_table(p, "id")
    with pytest.raises(CalibrationError, match="not a regular file|device"):
        load_limits("/dev/zero")
