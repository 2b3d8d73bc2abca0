"""Several boards at once: two simulated boards on two pseudo-terminals, one unplugged midway.
Every session file is compared row by row with the frames its board logged as sent."""

from __future__ import annotations

import io
import threading
import time

import numpy as np
import pytest
from triaxcal import sim
from triaxcal.capture.multi import (
    capture_many,
    parse_id_reply,
    port_label,
    query_serial_number,
)
from triaxcal.cli import main

RATE, SPEED = 100.0, 4.0


def board(seed: int, **kw) -> sim.SimDevice:
    script = sim.globe_script(hold_s=1.0, latitudes=3, turns=4, seed=seed)
    return sim.SimDevice(sim.SimIMU(seed), script, speed=SPEED, seed=seed, **kw)


def rows_of(path) -> tuple[np.ndarray, np.ndarray]:
    lines = path.read_text().splitlines()
    data = np.array([[float(v) for v in ln.split(",")] for ln in lines[1:]])
    return data[:, 0], data[:, 1:].astype(np.int64)


def test_two_boards_one_unplugged_nothing_lost(tmp_path):
    with board(1, serial="AX-0001") as a, board(2, serial="AX-0002") as b:
        unplug_at = {}

        def pull():
            unplug_at["before"] = len(a.sent)
            unplug_at["t"] = time.time()
            a.unplug(0.8)
            unplug_at["after"] = len(a.sent)
            unplug_at["t_back"] = time.time() + 0.8

        timer = threading.Timer(1.0, pull)
        timer.start()
        out = io.StringIO()
        boards = capture_many([a.port, b.port], tmp_path, protocol="framed", channels=10,
                              duration_s=3.0, progress=out, handle_sigint=False)
        timer.join()
        sent_a, sent_b = list(a.sent), list(b.sent)

    by_id = {x.board_id: x for x in boards}
    assert set(by_id) == {"AX-0001", "AX-0002"}
    assert all(x.ok and x.id_source == "serial" for x in boards)
    assert (tmp_path / "AX-0001.csv").exists() and (tmp_path / "AX-0002.csv").exists()
    ra, rb = by_id["AX-0001"].result, by_id["AX-0002"].result
    assert ra.stats.disconnects == 1 and ra.stats.reconnects == 1
    assert rb.stats.disconnects == 0
    assert "AX-0001" in out.getvalue() and "disconnected" in out.getvalue()

    # board B: a contiguous run of the frames it sent, none missing, none wrong, and it kept
    # capturing while A was away
    tb, vb = rows_of(tmp_path / "AX-0002.csv")
    vals_b = np.array([f.values for f in sent_b])
    start = int(np.flatnonzero((vals_b == vb[0]).all(axis=1))[0])
    assert np.array_equal(vb, vals_b[start:start + len(vb)])
    assert all(f.intact for f in sent_b[start:start + len(vb)])
    away = (tb > unplug_at["t"] + 0.1) & (tb < unplug_at["t_back"] - 0.1)
    assert away.sum() > 0.5 * RATE * SPEED

    # board A: every row is a frame it sent, in order; before the unplug nothing is missing
    # except the frames in flight in the pseudo-terminal when it vanished; once the board is
    # back and switched to its protocol again, nothing is missing
    ta, va = rows_of(tmp_path / "AX-0001.csv")
    vals_a = [f.values for f in sent_a]
    pos, j = [], 0
    for r in map(tuple, va):
        k = vals_a.index(r, j)
        pos.append(k)
        j = k + 1
    pos = np.array(pos)
    before, after = pos[pos < unplug_at["before"]], pos[pos >= unplug_at["after"]]
    assert len(before) > 100 and len(after) > 100
    assert np.array_equal(before, np.arange(before[0], before[-1] + 1))
    in_flight = unplug_at["before"] - 1 - before[-1]
    # only the frames in flight in the pseudo-terminal when it vanished (a fraction of a second;
    # the bound leaves room for a loaded machine, where the reader runs late)
    assert 0 <= in_flight <= 0.5 * RATE * SPEED
    assert np.array_equal(after, np.arange(after[0], after[-1] + 1))
    # the reader discards what arrives while it settles after re-sending the mode byte (20 ms
    # sleep, then it flushes its input as at the start of every capture; longer on a busy
    # machine)
    assert 0 <= after[0] - unplug_at["after"] <= 0.5 * RATE * SPEED


def test_boards_without_the_id_command_are_named_by_port(tmp_path, capsys):
    with board(3, serial=None) as a, board(4) as b:
        assert query_serial_number(a.port, timeout_s=0.3) is None
        assert query_serial_number(b.port) == "SIM-4"
        rc = main(["capture", "--port", a.port, "--port", b.port, "--protocol", "framed",
                   "--samples", "200", "--out-dir", str(tmp_path), "--no-bell"])
    assert rc == 0
    assert sorted(p.name for p in tmp_path.glob("*.csv")) == ["SIM-4.csv", "ttySIM0.csv"]
    for p in tmp_path.glob("*.csv"):
        assert len(p.read_text().splitlines()) == 201
    err = capsys.readouterr().err
    assert "SIM-4" in err and "ttySIM0" in err


def test_a_missing_port_fails_alone(tmp_path):
    with board(5) as a:
        boards = capture_many([a.port, str(tmp_path / "ttyGONE")], tmp_path / "s",
                              protocol="framed", channels=10, samples=150, progress=None,
                              handle_sigint=False, reader_options={"open_timeout_s": 0.3})
    ok, bad = boards
    assert ok.ok and ok.result.samples == 150
    assert not bad.ok and "does not exist" in bad.error and bad.board_id == "ttyGONE"
    assert not (tmp_path / "s" / "ttyGONE.csv").exists()


def test_same_serial_twice_gets_a_suffix(tmp_path):
    with board(6, serial="DUP") as a, board(7, serial="DUP") as b:
        boards = capture_many([a.port, b.port], tmp_path, protocol="framed", channels=10,
                              samples=50, progress=None, handle_sigint=False)
    assert [x.board_id for x in boards] == ["DUP", "DUP-2"]


def test_cli_rejects_out_with_several_ports(tmp_path, capsys):
    assert main(["capture", "--port", "a", "--port", "b", "--protocol", "framed",
                 "-o", str(tmp_path / "x.csv")]) == 1
    assert "--out-dir" in capsys.readouterr().err
    assert main(["capture", "--port", "a", "--port", "a", "--protocol", "framed",
                 "--out-dir", str(tmp_path)]) == 1
    assert "given twice" in capsys.readouterr().err


@pytest.mark.parametrize("reply,expected", [
    (b"ID:ABC123\r\n", "ABC123"),
    (b"\xff\xfe garbage ID:node_7.a-b\n", "node_7.a-b"),
    (b"ID:\r\n", None),
    (b"ID:a b\r\n", None),
    (b"ID:" + b"x" * 65 + b"\r\n", None),
    (b"ID:..\r\n", None),
    (b"ID:AB", None),
])
def test_id_replies_are_validated(reply, expected):
    assert parse_id_reply(reply) == expected


def test_port_labels_are_file_names():
    assert port_label("/dev/ttyUSB0") == "ttyUSB0"
    assert port_label("COM3") == "COM3"
    assert port_label("/dev/..") == "port"
