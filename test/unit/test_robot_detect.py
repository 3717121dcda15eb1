"""Contact detection on robots' recordings: the CSV reader, calibration from runs without
contact, the detectors and their score. The machinery is checked on a simulated chain whose
truth differs from its URDF in known ways; the figures on the real double pendulum are a
benchmark (benchmarks/pendubot_detection.py)."""

from __future__ import annotations

import lzma
from pathlib import Path

import numpy as np
import pytest

from transparency_ros.analysis import robot_detect as rd
from transparency_ros.analysis.robot_calibration import calibrate
from transparency_ros.analysis.robot_data import (
    Columns,
    JointRecording,
    read_joint_bag,
    read_joint_csv,
    write_joint_bag,
)
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.robot_calibration import Calibration
from transparency_ros.core.robot_model import RobotModel
from transparency_ros.synth.robots import chain_urdf, simulate_chain

HEADER = "time,pos_meas1,pos_meas2,vel_meas1,vel_meas2,tau_con1,tau_con2,tau_pert1,tau_pert2\n"


def write_csv(path: Path, rows: list[str]) -> Path:
    text = HEADER + "".join(r + "\n" for r in rows)
    if path.suffix == ".xz":
        path.write_bytes(lzma.compress(text.encode()))
    else:
        path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["run.csv", "run.csv.xz"])
def test_a_csv_is_read_per_joint_and_a_repeated_stamp_is_dropped_with_a_note(
    tmp_path: Path, name: str
) -> None:
    rows = [
        "0.000,0.1,0.2,1,2,0.5,0.6,0,0",
        "0.002,0.3,0.4,3,4,0.7,0.8,0,0.2",
        "0.002,9,9,9,9,9,9,9,9",  # the logger wrote the same time twice
        "0.004,0.5,0.6,5,6,0.9,1.0,0,0",
    ]
    rec = read_joint_csv(write_csv(tmp_path / name, rows), ["a", "b"])
    assert rec.joints == ("a", "b") and rec.stamps_ns.tolist() == [0, 2_000_000, 4_000_000]
    assert rec.position[:, 1].tolist() == [0.2, 0.4, 0.6]
    assert rec.torque[:, 0].tolist() == [0.5, 0.7, 0.9]
    assert rec.label is not None and rec.label[:, 1].tolist() == [0, 0.2, 0]
    assert rec.desired is None  # no pos_des columns
    assert rec.notes == [f"{name}: 1 row whose time does not increase dropped"]


def test_a_bad_csv_names_the_file_the_column_and_the_row(tmp_path: Path) -> None:
    bad = write_csv(tmp_path / "nan.csv", ["0,0,0,0,0,0,0,0,0", "0.002,0,nan,0,0,0,0,0,0"])
    with pytest.raises(ConfigError, match=r"nan\.csv: column 'pos_meas2' is not a finite .* row 3"):
        read_joint_csv(bad, ["a", "b"])
    good = write_csv(tmp_path / "good.csv", ["0,0,0,0,0,0,0,0,0", "0.002,0,0,0,0,0,0,0,0"])
    with pytest.raises(ConfigError, match=r"good\.csv: no column 'pos_meas3'"):
        read_joint_csv(good, ["a", "b", "c"])
    with pytest.raises(ConfigError, match="no column 'q1'"):
        read_joint_csv(good, ["a", "b"], Columns(position="q{}"))


def recording(label: np.ndarray, step_s: float = 0.002) -> JointRecording:
    n = label.shape[0]
    zeros = np.zeros((n, 2))
    stamps = (np.arange(n) * round(step_s * 1e9)).astype(np.int64)
    return JointRecording("r", stamps, ("a", "b"), zeros, zeros, zeros, label=label)


def test_the_score_counts_pulses_found_false_alarms_and_the_delay_from_half_the_peak() -> None:
    """Two triangular pulses on joint a (one found 10 ms after its half-peak, one missed), one
    on joint b found; three onsets elsewhere within 0.2 s are one false alarm, a fourth is
    another."""
    label = np.zeros((2000, 2))
    label[100:151, 0] = 0.4 * (1 - np.abs(np.arange(51) - 25) / 25)  # peak at 0.25 s
    label[1000:1051, 0] = 0.4 * (1 - np.abs(np.arange(51) - 25) / 25)
    label[500:551, 1] = -0.3 * (1 - np.abs(np.arange(51) - 25) / 25)
    rec = recording(label)
    pulses = rd.pulses(rec)
    assert [(p.joint, round(p.peak, 2)) for p in pulses] == [(0, 0.4), (0, 0.4), (1, 0.3)]
    half = pulses[0].half_s
    det = rd.Detection(
        "r",
        ("a", "b"),
        rec.stamps_ns * 1e-9,
        np.zeros((2000, 2)),
        np.ones((2000, 2)),
        [[half + 0.010, 3.0, 3.05, 3.1, 3.5], [pulses[2].half_s + 0.020]],
    )
    s = rd.score([det], [rec])
    assert (s.pulses, s.found, s.false_alarms) == (3, 2, 2)
    assert s.delays_s == pytest.approx([0.010, 0.020])
    assert [(m.recording, m.joint, m.half_s) for m in s.missed] == [("r", "a", pulses[1].half_s)]
    assert s.alarms_per_minute == pytest.approx(2 / (rec.duration_s / 60))
    only_b = rd.score([det], [rec], joint=1)
    assert (only_b.pulses, only_b.found, only_b.false_alarms) == (1, 1, 0)


def test_by_chance_is_what_the_same_onsets_find_of_the_labels_moved_in_time() -> None:
    """One pulse in 10 s: an onset on it finds it, and none of it moved 1.3-3.9 s later; an
    alarm every 0.1 s finds it wherever it is."""
    label = np.zeros((5000, 2))
    label[500:551, 0] = 0.4 * (1 - np.abs(np.arange(51) - 25) / 25)  # from 1.0 s
    rec = recording(label)
    t = rec.stamps_ns * 1e-9

    def det(onsets: list[float]) -> rd.Detection:
        return rd.Detection("r", ("a", "b"), t, np.zeros((5000, 2)), np.ones((5000, 2)),
                            [onsets, []])  # fmt: skip

    on_it = det([1.06])
    assert rd.score([on_it], [rec]).found == 1
    assert (rd.by_chance([on_it], [rec]).found, rd.by_chance([on_it], [rec]).pulses) == (0, 3)
    storm = det(list(np.arange(0.0, 10.0, 0.1)))
    assert rd.by_chance([storm], [rec], joint=0).recall == 1.0
    assert rd.by_chance([storm], [rec], joint=0).pulses == 3  # the pulse, once per shift


def simulated(model: RobotModel, seconds: float, phase: float, pulses: list[tuple[int, float]]
              ) -> JointRecording:  # fmt: skip
    """The true chain's run at 1 kHz, the motors 4 ms late, 0.4 N m pushes of 0.3 s."""
    n = round(seconds * 1000)
    tau_ext = np.zeros((n, model.dof))
    for joint, start_s in pulses:
        tau_ext[round(start_s * 1000) : round((start_s + 0.3) * 1000), joint] = 0.4
    stamps, q, v, command = simulate_chain(model, tau_ext, delay_steps=4, phase=phase)
    return JointRecording(f"run{phase:g}", stamps, model.joint_names, q, v, command, label=tau_ext)


def test_calibration_learns_the_delay_and_the_mass_the_urdf_lacks_and_then_detects() -> None:
    """The chain is 30 % heavier than its URDF says and its motors apply the command 4 ms
    late. Calibrated on three runs without contact, the detector finds all four pushes of a
    fourth run with no false alarm; the URDF's model as it is, with a threshold just above
    its largest residual without contact, finds fewer."""
    urdf = RobotModel.from_urdf(chain_urdf(2))
    truth = RobotModel.from_urdf(chain_urdf(2, mass=0.65))
    clean = [simulated(truth, 5.0, phase, []) for phase in (0.0, 1.0, 2.0)]
    cal = calibrate(urdf, clean, gain_per_s=20.0)
    # 4 samples late, each command held for its 1 ms step: 4.5 ms in effect
    assert cal.command_delay_s in {0.004, 0.005}
    command_rms = np.sqrt(np.mean(np.concatenate([r.torque for r in clean]) ** 2))
    assert cal.torque_rms_nm < 0.02 * command_rms
    for q in ([0.3, 0.5], [1.0, -0.4]):  # the weight it learnt is the true one
        learnt, true = cal.model(urdf).gravity(np.array(q)), truth.gravity(np.array(q))
        assert learnt == pytest.approx(true, rel=0.02)
        assert urdf.gravity(np.array(q)) != pytest.approx(true, rel=0.1)
    pushed = simulated(truth, 6.0, 0.5, [(0, 1.0), (1, 2.5), (0, 4.0), (1, 5.0)])
    s = rd.score([rd.calibrated(urdf, cal, pushed)], [pushed])
    assert (s.found, s.pulses, s.false_alarms) == (4, 4, 0)
    assert s.delay_s(50) < 0.1
    thresholds = rd.constant_thresholds([rd.textbook_residual(urdf, r, 20.0) for r in clean])
    textbook = rd.with_threshold(pushed, rd.textbook_residual(urdf, pushed, 20.0), thresholds)
    assert rd.score([textbook], [pushed]).found < 4


def test_a_calibration_round_trips_and_refuses_another_robot(tmp_path: Path) -> None:
    urdf = RobotModel.from_urdf(chain_urdf(2))
    clean = [simulated(urdf, 3.0, 0.0, [])]
    cal = calibrate(urdf, clean, gain_per_s=20.0)
    cal.save(tmp_path / "cal.yaml")
    again = Calibration.load(tmp_path / "cal.yaml")
    assert again == cal
    with pytest.raises(ConfigError, match="a calibration from another robot"):
        again.model(RobotModel.from_urdf(chain_urdf(3)))
    (tmp_path / "bad.yaml").write_text("robot: x\njoints: [a]\n")
    with pytest.raises(ConfigError, match=r"bad\.yaml: not a calibration file"):
        Calibration.load(tmp_path / "bad.yaml")


SHARED = Path(__file__).resolve().parents[1] / "data" / "double_pendulum"  # the lab's files


def test_calibrate_and_detect_on_the_real_double_pendulum_from_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The commands a user types, on the lab's recordings: calibrate on two clean runs, detect
    on a disturbed one with its labels, a plot per recording; and one clear line when the
    calibration is missing."""
    from transparency_ros.cli import main  # noqa: PLC0415

    urdf = str(SHARED / "pendubot.urdf")
    clean = [str(SHARED / f"pendubot_clean_0{k}.csv.xz") for k in (1, 2)]
    assert main(["calibrate", *clean, "--urdf", urdf, "--out", str(tmp_path / "cal.yaml")]) == 0
    out = capsys.readouterr()
    assert "calibrated pendulum_mj_bots_001 (Joint1, Joint2) on 2 recordings" in out.out
    assert "taken as the fixed world" in out.err
    assert "positive definite at 0% of the configurations" in out.out
    assert "fits the torque balance, not the physics" in out.err  # and says what that means
    pert = str(SHARED / "pendubot_pert_01.csv.xz")
    args = ["detect", pert, "--urdf", urdf, "--labels", "tau_pert{}"]
    code = main([*args, "--calibration", str(tmp_path / "cal.yaml"), "--report", str(tmp_path)])
    assert code == 0
    out = capsys.readouterr().out
    assert "pendubot_pert_01 Joint1: contact onsets at [s]" in out
    assert "Joint2: " in out and " pulses found, " in out and "false alarms" in out
    assert "of the pulses would be found by chance" in out
    assert (tmp_path / "pendubot_pert_01.png").stat().st_size > 10_000
    assert main(args) == 2
    assert "--method momentum_observer needs --calibration" in capsys.readouterr().err


def test_calibrate_and_detect_read_bags_of_states_and_commands(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same simulated chain recorded as bags (/joint_states and /joint_commands' efforts):
    read back exactly, calibrated on two, and the pushes of a third are detected."""
    from transparency_ros.cli import main  # noqa: PLC0415

    truth = RobotModel.from_urdf(chain_urdf(2, mass=0.65))
    runs = [simulated(truth, 4.0, phase, []) for phase in (0.0, 1.0)]
    runs.append(simulated(truth, 4.0, 0.5, [(0, 1.0), (1, 2.5)]))
    epoch = 1_800_000_000 * 10**9  # a robot's clock
    bags = [write_joint_bag(tmp_path / f"run{k}", r, start_ns=epoch) for k, r in enumerate(runs)]
    back = read_joint_bag(bags[2], ["j0", "j1"])
    assert back.stamps_ns.tolist() == runs[2].stamps_ns.tolist()
    assert np.array_equal(back.position, runs[2].position)
    assert np.array_equal(back.torque, runs[2].torque)  # each sample's own command
    (tmp_path / "chain.urdf").write_text(chain_urdf(2))
    urdf = str(tmp_path / "chain.urdf")
    cal = str(tmp_path / "cal.yaml")
    assert main(["calibrate", str(bags[0]), str(bags[1]), "--urdf", urdf, "--out", cal]) == 0
    calibrated = capsys.readouterr()
    assert "positive definite at 100% of the configurations" in calibrated.out
    assert "not the physics" not in calibrated.err
    assert main(["detect", str(bags[2]), "--urdf", urdf, "--calibration", cal]) == 0
    out = capsys.readouterr().out
    onsets = {
        line.split(":")[0]: line.split("[s] ")[1] for line in out.splitlines() if "[s]" in line
    }
    assert float(onsets["run2 j0"].split(",")[0]) == pytest.approx(1.0, abs=0.05)
    assert float(onsets["run2 j1"].split(",")[0]) == pytest.approx(2.5, abs=0.05)
    with pytest.raises(ConfigError, match=r"/joint_states has no joint \['j9'\]"):
        read_joint_bag(bags[0], ["j0", "j9"])


def test_import_csv_of_several_joints_writes_bags_that_detect_reads_as_the_csv(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The lab's CSVs imported as a robot's bags (/joint_states, /joint_commands,
    /true_external_effort): read back, every column is the CSV's, and calibrate and detect
    print the same on the bags as on the CSVs."""
    from transparency_ros.cli import main  # noqa: PLC0415

    csvs = [str(SHARED / f"pendubot_{n}.csv.xz") for n in ("clean_01", "pert_01")]
    out = tmp_path / "bags"
    assert main(["import-csv", *csvs, "--out", str(out), "--joints", "Joint1,Joint2"]) == 0
    printed = capsys.readouterr().out
    assert "pendubot_pert_01  (" in printed and "with measured, labels)" in printed
    assert "pendubot_clean_01  (" in printed and "with measured, desired)" in printed
    joints = ["Joint1", "Joint2"]
    columns = Columns(measured="tau_meas{}")
    for name in ("clean_01", "pert_01"):
        csv = read_joint_csv(SHARED / f"pendubot_{name}.csv.xz", joints, columns)
        bag = read_joint_bag(out / f"pendubot_{name}", joints, "/true_external_effort")
        assert bag.name == csv.name
        assert bag.stamps_ns.tolist() == csv.stamps_ns.tolist()
        for field in ("position", "velocity", "torque", "measured", "desired", "label"):
            mine, theirs = getattr(bag, field), getattr(csv, field)
            assert (mine is None) == (theirs is None), field
            assert mine is None or np.array_equal(mine, theirs), field
    urdf = str(SHARED / "pendubot.urdf")
    lines = []
    for clean, pert in ((csvs[0], csvs[1]), *[[str(out / f"pendubot_{n}") for n in
                                               ("clean_01", "pert_01")]]):  # fmt: skip
        cal = str(tmp_path / "cal.yaml")
        assert main(["calibrate", clean, "--urdf", urdf, "--out", cal]) == 0
        args = ["detect", pert, "--urdf", urdf, "--calibration", cal, "--labels", "tau_pert{}"]
        assert main(args) == 0
        lines.append(capsys.readouterr().out.replace(cal, "").splitlines())
        (tmp_path / "cal.yaml").unlink()
    assert lines[0] == lines[1]
    assert any("pulses found" in line for line in lines[0])


def test_import_csv_of_several_joints_refuses_bad_input_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from transparency_ros.cli import main  # noqa: PLC0415

    good = str(SHARED / "pendubot_pert_01.csv.xz")
    bad = tmp_path / "three.csv"
    bad.write_text("time,pos_meas1,vel_meas1,tau_con1\n0,0,0,0\n0.002,0,0,nan\n")
    out = tmp_path / "bags"
    assert main(["import-csv", good, str(bad), "--out", str(out), "--joints", "a,b"]) == 2
    assert "three.csv: no column 'pos_meas2'" in capsys.readouterr().err
    assert not out.exists() or not any(out.iterdir())  # not even the good file's bag
    assert main(["import-csv", str(bad), "--out", str(out), "--joints", "a"]) == 2
    assert "'tau_con1' is not a finite number in row 3" in capsys.readouterr().err
    assert main(["import-csv", good, "--out", str(out), "--joints", "a,a"]) == 2
    assert "needs distinct, non-empty names" in capsys.readouterr().err
    assert main(["import-csv", good, "--out", str(out), "--joints", "a,b"]) == 0
    assert main(["import-csv", good, "--out", str(out), "--joints", "a,b"]) == 2
    assert "exist already" in capsys.readouterr().err
    args = ["import-csv", good, "--out", str(tmp_path / "x"), "--joints", "a,b"]
    assert main([*args, "--columns", "time=time,speed=v{}"]) == 2
    assert "'speed=v{}' is not one of" in capsys.readouterr().err


def test_episodes_give_each_onset_its_release_and_signed_peak() -> None:
    t = np.arange(30) * 0.002
    residual = np.zeros((30, 1))
    residual[10:15, 0] = [-2.0, -2.5, -3.0, -1.0, -0.8]  # onset at 10, peak -3 at 12
    residual[15, 0] = -0.5  # back to half the threshold: released here (as the node does)
    residual[25:, 0] = 1.5  # a second contact still on at the end
    det = rd.with_threshold(
        JointRecording("r", (t * 1e9).astype(np.int64), ("a",), residual, residual, residual),
        residual,
        np.ones(1),
    )
    assert det.onsets_s == [[pytest.approx(t[10]), pytest.approx(t[25])]]
    ((first, second),) = rd.episodes(det)
    assert (first.onset_s, first.release_s) == pytest.approx((t[10], t[15]))
    assert first.peak_residual == -3.0
    assert second.onset_s == pytest.approx(t[25])
    assert (second.release_s, second.peak_residual) == (None, 1.5)


def test_a_one_joint_robot_is_calibrated_and_detected_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The AK80-6 pendulum with its URDF: pinocchio gives a one-joint robot's regressor as a
    vector, and calibrate stopped with numpy's AxisError."""
    from transparency_ros.cli import main  # noqa: PLC0415

    data = Path(__file__).resolve().parents[1] / "data" / "ak80_6_pendulum"
    common = [str(data / "energy_shaping_data_measured.csv"), "--urdf",
              str(data / "dfki_simple_pendulum.urdf"), "--columns",
              "time=time,position=position,velocity=velocity,torque=torque"]  # fmt: skip
    cal = str(tmp_path / "cal.yaml")
    assert main(["calibrate", *common, "--out", cal]) == 0
    out = capsys.readouterr().out
    assert "calibrated Einfachpendel_1 (Joint_1) on 1 recording: " in out
    assert "positive definite at 100% of the configurations" in out
    assert main(["detect", *common, "--calibration", cal]) == 0
    assert "energy_shaping_data_measured Joint_1: contact onsets at [s]" in capsys.readouterr().out
