"""The parameter table of ``contact_estimator`` and what is built from it (detector settings,
the momentum observer's pipeline). The node declares them from here, ``--help`` prints them, and
the docs and config/contact_estimator.yaml are generated from and tested against them."""

from __future__ import annotations

import math
from typing import Any

from rclpy.qos import DurabilityPolicy, QoSProfile

from transparency_ros.core.errors import ConfigError
from transparency_ros.core.estimator import DetectorSettings, SchmittDetector
from transparency_ros.core.robot_pipeline import ObserverPipeline
from transparency_ros.ros.params import ParamSpec

NODE_NAME = "contact_estimator"
METHODS = ("position_error", "momentum_observer")
P = ParamSpec
PARAMETERS: tuple[ParamSpec, ...] = (
    P(
        "method",
        "position_error",
        "position_error: eq. (1), k_s (theta_d - theta_a); momentum_observer: the "
        "generalized-momentum observer of a robot model (robot_description), driven by the "
        "efforts of /joint_commands",
        read_only=True,
        choices=METHODS,
    ),
    P(
        "robot_description",
        "",
        "momentum_observer: the URDF, as XML or a file path (as robot_state_publisher takes it); "
        "'': the latest on the /robot_description topic (as robot_state_publisher publishes it)",
        read_only=True,
    ),
    P(
        "calibration_file",
        "",
        "momentum_observer: a calibration YAML from `transparency calibrate` ('': none)",
        read_only=True,
    ),
    P(
        "observer_gain_per_s",
        20.0,
        "momentum_observer: gain K_o [1/s] (a calibration sets its own)",
        read_only=True,
        low=0.1,
        high=1000.0,
    ),
    P(
        "observer_threshold_nm",
        0.5,
        "momentum_observer without a calibration: |residual| that starts a contact [N m]",
        read_only=True,
        low=1e-6,
        high=1000.0,
    ),
    P("joints", [""], "joint names to accept ([''] : any)", read_only=True),
    P(
        "use_setpoints",
        True,
        "position_error: theta_d from the driver's /joint_setpoints, paired with each sample by "
        "stamp, when they come (else, and for joints without them, from /joint_commands)",
        read_only=True,
    ),
    P(
        "setpoint_wait_s",
        0.02,
        "how long a sample waits, from its arrival, for its /joint_setpoints; then the "
        "setpoint of the nearest stamp stands in and the loss is reported",
        read_only=True,
        low=0.0,
        high=1.0,
    ),
    P("theta_d_rad", 0.0, "theta_d for joints without /joint_commands [rad]"),
    P(
        "k_s",
        2.0,
        "virtual spring k_s of the impedance controller [N m/rad]",
        low=1e-6,
        high=1000.0,
    ),
    P("k_d", 0.0, "k_d term of the full estimate [N m s/rad]", low=0.0, high=100.0),
    P(
        "beta",
        0.0,
        "back-EMF term -beta theta_a' of the full estimate [N m s/rad]",
        low=0.0,
        high=100.0,
    ),
    P(
        "contact_onset_rad",
        0.1,
        "|error - bias| that starts a contact (paper: 0.1 rad drop tests)",
        low=1e-6,
        high=10.0,
    ),
    P(
        "contact_release_rad",
        0.05,
        "|error - bias| that ends it (below the onset)",
        low=0.0,
        high=10.0,
    ),
    P("collision_onset_rad", 0.0, "collision level (0: off)", low=0.0, high=10.0),
    P("collision_release_rad", 0.0, "collision release level (0: off)", low=0.0, high=10.0),
    P(
        "onset_dwell_s",
        0.0,
        "time beyond the onset level before an onset is confirmed",
        low=0.0,
        high=10.0,
    ),
    P("release_dwell_s", 0.0, "time below the release level before a release", low=0.0, high=10.0),
    P(
        "bias_rad",
        0.0,
        "known steady error subtracted before thresholding [rad]",
        low=-10.0,
        high=10.0,
    ),
    P(
        "arm_length_m",
        0.0,
        "contact force = tau_hat / arm_length (0: not published)",
        low=0.0,
        high=10.0,
    ),
    P("diagnostics_period_s", 1.0, "/diagnostics period [s]", read_only=True, low=0.01, high=60.0),
    P(
        "queue_depth",
        1000,
        "/joint_states samples kept while the node catches up (0.1 s at 10 kHz)",
        read_only=True,
        low=1,
        high=100000,
    ),
    P(
        "hot_path_priority",
        0,
        "SCHED_FIFO priority (1-99) of the thread serving /joint_states; 0: normal scheduling. "
        "Needs CAP_SYS_NICE or an rtprio limit; refused, the node warns and runs as normal",
        read_only=True,
        low=0,
        high=99,
    ),
    P(
        "in_process",
        False,
        "take /joint_states only from a source composed into this process (ros.in_process: "
        "no DDS on the way in; for one process with the driver)",
        read_only=True,
    ),
)
DETECTOR_PARAMS = {
    "contact_onset_rad": "contact_onset", "contact_release_rad": "contact_release",
    "collision_onset_rad": "collision_onset", "collision_release_rad": "collision_release",
    "onset_dwell_s": "onset_dwell_s", "release_dwell_s": "release_dwell_s", "bias_rad": "bias",
}  # fmt: skip
GAIN_PARAMS = {"k_s": "k_s_nm_per_rad", "k_d": "k_d_nms_per_rad", "beta": "beta_nms_per_rad"}
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)


def detector_settings(values: dict[str, Any]) -> DetectorSettings:
    kwargs = {field: values[name] for name, field in DETECTOR_PARAMS.items()}
    for key in ("collision_onset", "collision_release"):
        if kwargs[key] == 0.0:
            kwargs[key] = math.inf
    return DetectorSettings(**kwargs).validated()


def observer_settings(values: dict[str, Any]) -> DetectorSettings:
    """The momentum observer's trigger works on |residual| / threshold: onset at 1, release at
    0.5; the dwell times are the node's."""
    return DetectorSettings(
        contact_onset=1.0,
        contact_release=0.5,
        onset_dwell_s=values["onset_dwell_s"],
        release_dwell_s=values["release_dwell_s"],
    ).validated()


def load_calibration(values: dict[str, Any]) -> Any:
    """The ``calibration_file``'s calibration, None without one; a ConfigError naming a file
    that is missing or not a calibration."""
    from transparency_ros.core.robot_calibration import Calibration  # noqa: PLC0415

    return Calibration.load(values["calibration_file"]) if values["calibration_file"] else None


def observer_pipeline(values: dict[str, Any], calibration: Any = None) -> ObserverPipeline:
    """The ``momentum_observer`` method's pipeline, with ``calibration`` (default: loaded from
    ``calibration_file``): a clear ConfigError for a missing or bad URDF, or a calibration from
    another robot."""
    from transparency_ros.core.robot_model import RobotModel  # noqa: PLC0415

    if not values["robot_description"].strip():
        raise ConfigError("method momentum_observer needs a URDF (robot_description is empty)")
    model = RobotModel.from_urdf(values["robot_description"])
    if calibration is None:
        calibration = load_calibration(values)
    return ObserverPipeline(
        model,
        values["observer_gain_per_s"],
        SchmittDetector(observer_settings(values)),
        calibration,
        values["observer_threshold_nm"],
    )
