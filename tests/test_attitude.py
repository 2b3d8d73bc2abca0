"""Compass calibration from a flight's attitude (triaxcal.methods.attitude,
triaxcal.calibration.flight) on the simulated flight with truth and the real logs."""

import json
from pathlib import Path

import numpy as np
import pytest
import triaxcal as tc
from triaxcal.calibration.flight import fit_flight
from triaxcal.calibration.gate import check_part
from triaxcal.calibration.request import FieldOptions, FitRequest
from triaxcal.sim.flight import write_flight

pytest.importorskip("pymavlink")
REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata"
ERLE = REAL / "ardupilot-erle-logs"


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    pytest.importorskip("wmm")
    ef = tc.expected_field(47.37, 8.54, 400.0, date="2026-06-01")
    return write_flight(tmp_path_factory.mktemp("flight"), np.array(ef.vector_ned_ut()) * 10.0)


def test_simulated_flight_recovers_offsets_and_interference(flight):
    req = FitRequest(sensor="mag", method="attitude",
                     field=FieldOptions(location=(47.37, 8.54, 400.0), date="2026-06-01"))
    part, _ = fit_flight(flight["log"], req)
    truth = json.loads(flight["truth"].read_text())
    field = np.linalg.norm(truth["field_mG"])
    assert np.linalg.norm(-part.offset - truth["COMPASS_OFS"]) <= 0.01 * field
    mot = np.asarray(part.stats["interference"]["vector"])
    assert np.linalg.norm(mot - truth["COMPASS_MOT"]) <= 0.05 * np.linalg.norm(truth["COMPASS_MOT"])
    assert check_part(part, "mag").valid
    held = part.stats["attitude"]["held_out"]
    assert held["scatter_after"] * 2 <= held["scatter_before"]
    from triaxcal.export.ardupilot import ardupilot_params

    params = ardupilot_params(tc.Calibration(mag=part))
    assert params["COMPASS_MOTCT"] == 2.0
    assert abs(params["COMPASS_MOT_Z"] - truth["COMPASS_MOT"][2]) < 0.25


@pytest.mark.skipif(not ERLE.is_dir(), reason="real logs not present")
@pytest.mark.parametrize("name", ["PXFv2.0b+Rpi.BIN", "Erle-Brain3.BIN"])
def test_real_ardupilot_logs_are_refused_with_the_reason(name):
    part, _ = fit_flight(ERLE / name, FitRequest(sensor="mag", method="attitude"))
    v = check_part(part, "mag")
    assert not v.valid
    assert any("does not determine" in r or "does not hold still" in r for r in v.reasons)


@pytest.mark.skipif(not ERLE.is_dir(), reason="real logs not present")
def test_log_without_attitude_is_refused(tmp_path):
    table = tmp_path / "mag.csv"
    table.write_text("mx,my,mz\n" + "\n".join(f"{i},{-i},{i * 2}" for i in range(50)))
    with pytest.raises(tc.CalibrationError, match="flight log|attitude"):
        tc.fit_session(table, FitRequest(sensor="mag", method="attitude"))
