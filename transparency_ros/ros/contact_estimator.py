"""Node ``contact_estimator``: tau_hat = k_s (theta_d - theta_a) and contact events.

Subscribes /joint_states and /joint_commands (theta_d; the ``theta_d_rad`` parameter stands in
for joints without commands). With ``method:=momentum_observer`` it runs instead the
generalized-momentum observer of the robot in ``robot_description`` (a URDF), driven by the
commanded efforts of /joint_commands (by joint name), with a calibration from
``transparency calibrate`` if given (``core.robot_pipeline``); /estimated_effort's effort is then
the estimated external torque and its position the share of the threshold (1: contact).
Publishes, with standard interfaces only:

* /estimated_effort  sensor_msgs/JointState: effort = tau_hat, position = theta_d - theta_a,
  header.stamp = the source sample's stamp;
* /contact           geometry_msgs/WrenchStamped, one per contact onset: stamp = the sample that
  crossed the threshold, frame_id = joint, torque.z = tau_hat [N m], force.z = tau_hat /
  arm_length_m [N] when arm_length_m > 0;
* /collision         the same, one per collision-level onset (when that level is configured);
* /contact_release   the same, one per release (stamp = first sample back below the release
  level);
* ~/state/<joint>    std_msgs/UInt8, latched (transient local): 0 no contact, 1 contact,
  2 collision, published on every change;
* /diagnostics       rates, rejected samples by reason, processing time, sample age, events.

Bad samples are rejected and counted, never crash the node. The logic is in
``core.estimator`` (EstimatorPipeline); this file converts messages and parameters.

/joint_states is served by the node's own thread as serialized bytes (``ros.hot_path``, decoded
by ``core.cdr``; anything else, such as big-endian CDR, goes through rclpy's deserializer), and
the per-sample outputs are published as bytes: the rest of the node runs on whichever executor it
is added to. ``self.lock`` guards the pipeline between the two.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import replace
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import String, UInt8
from std_srvs.srv import Trigger

from transparency_ros.core import stamps
from transparency_ros.core.cdr import (
    CdrError,
    JointStateFields,
    JointStateReader,
    encode_joint_state,
    encode_wrench_stamped,
)
from transparency_ros.core.errors import ConfigError
from transparency_ros.core.estimator import (
    ContactEvent,
    DetectorSettings,
    EstimatorError,
    EstimatorGains,
    EstimatorPipeline,
    EventKind,
    SampleRejectedError,
    SchmittDetector,
)
from transparency_ros.core.histogram import DurationHistogram
from transparency_ros.core.robot_pipeline import AwaitingModel, ObserverPipeline
from transparency_ros.ros import in_process
from transparency_ros.ros.conversions import stamp_to_ns
from transparency_ros.ros.hot_path import Delivery, HotPath
from transparency_ros.ros.params import (
    ParamSpec,
    accept_integers_for_doubles,
    check_unknown,
    choice_error,
    declare,
    run_node,
)

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


class ContactEstimatorNode(Node):
    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.values = declare(self, PARAMETERS)
        check_unknown(self, refuse=False)  # it commands nothing: run on, with a warning
        accept_integers_for_doubles(self, PARAMETERS)
        if self.values["method"] != "momentum_observer":
            unused = [n for n in ("robot_description", "calibration_file") if self.values[n]]
            if unused:
                self.get_logger().warning(
                    f"{', '.join(unused)} ignored: only method:=momentum_observer uses them "
                    f"(method is {self.values['method']})"
                )
        joints = frozenset(j for j in self.values["joints"] if j)
        self.pipeline: EstimatorPipeline | ObserverPipeline | AwaitingModel
        self._description = ""  # the URDF the observer was built from, if from the topic
        self._calibration: Any = None  # loaded at start when the URDF is to come by topic
        if self.values["method"] == "momentum_observer" and self.values["robot_description"]:
            self.pipeline = observer_pipeline(self.values)
        elif self.values["method"] == "momentum_observer":
            # a bad calibration file is refused now, not when the URDF comes
            self._calibration = load_calibration(self.values)
            self.pipeline = AwaitingModel()
            self.create_subscription(String, "/robot_description", self._on_description, LATCHED)
        else:
            self.pipeline = EstimatorPipeline(
                gains=EstimatorGains(
                    **{f: self.values[n] for n, f in GAIN_PARAMS.items()}
                ).validated(),
                detector=SchmittDetector(detector_settings(self.values)),
                joints=joints,
                default_theta_d_rad=self.values["theta_d_rad"],
            )
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        self._estimate_pub = self.create_publisher(JointState, "/estimated_effort", 100)
        self._event_pubs = {
            EventKind.CONTACT_ONSET: self.create_publisher(WrenchStamped, "/contact", 10),
            EventKind.COLLISION_ONSET: self.create_publisher(WrenchStamped, "/collision", 10),
            EventKind.RELEASE: self.create_publisher(WrenchStamped, "/contact_release", 10),
        }
        self._state_pubs: dict[str, Any] = {}
        self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.lock = threading.Lock()  # the pipeline and the statistics, across the two threads
        # the momentum observer needs every command's effort, not the latest few
        depth = self.values["queue_depth"] if self.values["method"] == "momentum_observer" else 10
        self.create_subscription(JointState, "/joint_commands", self._on_command, depth)
        self.create_service(Trigger, "~/reset", self._on_reset)
        self.create_timer(self.values["diagnostics_period_s"], self._publish_diagnostics)
        self.events_published = 0
        # per diagnostics period: samples arrived, time in the /joint_states handler
        self._period_start_s = time.monotonic()
        self._period_arrivals = 0
        self.handler_time = DurationHistogram()
        # since start (or ~/reset): wall-clock time at the publish call - the sample's stamp
        # (meaningful when the source stamps with this machine's clock, as the driver does), of
        # every estimate and every onset
        self.sample_age = DurationHistogram()
        self.onset_age = DurationHistogram()
        self._last_warn_s = -math.inf
        self._reader = JointStateReader()
        self.hot_path = HotPath(self, priority=self.values["hot_path_priority"])
        self._leave_in_process = None
        self.delivery: Delivery | None = None  # what DDS delivered and lost (not in-process)
        if self.values["in_process"]:
            self._leave_in_process = in_process.subscribe(
                self.context, "/joint_states", self.hot_path.guarded(self._on_state_bytes)
            )
        else:
            sub = self.hot_path.subscribe(
                JointState, "/joint_states", self.values["queue_depth"], self._on_state_bytes
            )
            self.delivery = self.hot_path.delivery(sub)
            self.hot_path.start()

    def destroy_node(self) -> None:
        if self._leave_in_process is not None:
            self._leave_in_process()
        if not self.hot_path.stop():
            self.get_logger().error("hot path thread still running: node left undestroyed")
            return
        super().destroy_node()

    # ----------------------------------------------------------------- parameters

    def _validate(self, params: list[Parameter]) -> SetParametersResult:
        trial = dict(self.values)
        for p in params:
            reason = choice_error(PARAMETERS, p.name, p.value)
            if reason:
                return SetParametersResult(successful=False, reason=reason)
            trial[p.name] = p.value
        try:
            detector_settings(trial)
            EstimatorGains(**{f: trial[n] for n, f in GAIN_PARAMS.items()}).validated()
        except EstimatorError as err:
            return SetParametersResult(successful=False, reason=str(err))
        return SetParametersResult(successful=True)

    def _apply(self, params: list[Parameter]) -> None:
        for p in params:
            self.values[p.name] = p.value
        if isinstance(self.pipeline, AwaitingModel):
            return  # the pipeline built on arrival takes self.values
        if isinstance(self.pipeline, ObserverPipeline):
            with self.lock:
                self.pipeline.detector.default = observer_settings(self.values)
            return
        gains = EstimatorGains(**{f: self.values[n] for n, f in GAIN_PARAMS.items()}).validated()
        with self.lock:
            self.pipeline.gains = gains
            self.pipeline.detector.default = detector_settings(self.values)
            self.pipeline.default_theta_d_rad = self.values["theta_d_rad"]

    # ----------------------------------------------------------------- data

    def _warn(self, text: str) -> None:
        now = time.monotonic()
        if now - self._last_warn_s >= 1.0:
            self._last_warn_s = now
            self.get_logger().warning(text)

    def _on_description(self, msg: String) -> None:
        """A URDF on /robot_description: the observer is (re)built from it. A URDF that does
        not load, or that a calibration does not fit, is logged and the model in use kept."""
        if msg.data == self._description:
            return
        try:
            values = {**self.values, "robot_description": msg.data}
            pipeline = observer_pipeline(values, self._calibration)
        except (ConfigError, EstimatorError) as err:
            self.get_logger().error(f"/robot_description not used: {err}")
            return
        with self.lock:
            kept = dict(self.pipeline.rejected)
            pipeline.rejected.update(kept)
            replaced = isinstance(self.pipeline, ObserverPipeline)
            self.pipeline = pipeline
            self._description = msg.data
        joints = ", ".join(pipeline.model.joint_names)
        self.get_logger().info(
            f"robot model {'replaced' if replaced else 'received'} from /robot_description: "
            f"{pipeline.model.dof} joints ({joints})"
        )

    def _on_command(self, msg: JointState) -> None:
        try:
            stamp_ns = stamp_to_ns(msg.header.stamp)
            args = (
                list(msg.name),
                list(msg.position),
                list(msg.velocity),
                stamp_ns if stamp_ns > 0 else None,
            )
            with self.lock:
                if isinstance(self.pipeline, (ObserverPipeline, AwaitingModel)):
                    self.pipeline.command(*args, efforts=list(msg.effort))
                else:
                    self.pipeline.command(*args)
        except SampleRejectedError as err:
            self._warn(f"rejected /joint_commands: {err}")

    def _decode(self, data: bytes) -> JointStateFields | None:
        """Called with ``self.lock`` held (the reader keeps the stream's layout)."""
        try:
            return self._reader(data)
        except CdrError as fast_error:
            try:  # what core.cdr does not read (big-endian CDR): rclpy's deserializer
                msg = deserialize_message(data, JointState)
            except Exception:  # noqa: BLE001 - any failure means the bytes are not a JointState
                self.pipeline.reject("undecodable", str(fast_error))
                self._warn(f"rejected /joint_states: not a JointState ({fast_error})")
                return None
        stamp = msg.header.stamp
        return JointStateFields(
            stamp.sec, stamp.nanosec, msg.header.frame_id, list(msg.name),
            tuple(msg.position), tuple(msg.velocity), tuple(msg.effort),
        )  # fmt: skip

    def _on_state_bytes(self, data: bytes) -> None:
        started = time.perf_counter()
        with self.lock:
            sample = self._decode(data)
            if sample is None:
                return
            stamp_ns = sample.stamp_ns
            self._period_arrivals += 1
            try:
                estimates, events = self.pipeline.sample(
                    stamp_ns,
                    sample.name,
                    list(sample.position),
                    list(sample.velocity),
                )
            except SampleRejectedError as err:
                self._warn(f"rejected /joint_states: {err}")
                return
            for event in events:  # first: a behavior waits for them
                self._publish_event(event, stamp_ns)
            out = encode_joint_state(
                sample.sec,
                sample.nanosec,
                "",
                [e.joint for e in estimates],
                position=[e.error_rad for e in estimates],
                effort=[e.torque_nm for e in estimates],
            )
            # the age at the publish call, as the source's stamp is (delivery is after both)
            self.sample_age.add((time.time_ns() - stamp_ns) * 1e-9)
            self._estimate_pub.publish(out)
            self.handler_time.add(time.perf_counter() - started)

    def _publish_event(self, event: ContactEvent, stamp_ns: int) -> None:
        """Publish an event of the sample stamped ``stamp_ns`` (the sample that triggered it)."""
        pub = self._event_pubs.get(event.kind)
        if pub is not None:
            arm = self.values["arm_length_m"]
            force = event.torque_nm / arm if arm > 0 else 0.0
            sec, nanosec = stamps.split(event.stamp_ns)  # exact: the sample's own stamp
            data = encode_wrench_stamped(
                sec,
                nanosec,
                event.joint,
                (0.0, 0.0, force),
                (0.0, 0.0, event.torque_nm),
            )
            if event.kind is not EventKind.RELEASE:
                self.onset_age.add((time.time_ns() - stamp_ns) * 1e-9)
            pub.publish(data)
            self.events_published += 1
        state_pub = self._state_pubs.get(event.joint)
        if state_pub is None:
            state_pub = self.create_publisher(UInt8, f"~/state/{event.joint}", LATCHED)
            self._state_pubs[event.joint] = state_pub
        state_pub.publish(UInt8(data=int(event.level)))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response) -> Any:
        with self.lock:
            self.pipeline.reset()
            self.handler_time.reset()
            self.sample_age.reset()
            self.onset_age.reset()
            if self.delivery is not None:
                self.delivery.reset()
        for pub in self._state_pubs.values():
            pub.publish(UInt8(data=0))
        response.success = True
        response.message = "detector state, stamp history and latency statistics cleared"
        return response

    def _publish_diagnostics(self) -> None:
        status = DiagnosticStatus(name=f"{NODE_NAME}: estimator", hardware_id="")
        now = time.monotonic()
        with self.lock:  # snapshots (microseconds); the work below does not hold up the hot path
            rate = self._period_arrivals / max(now - self._period_start_s, 1e-9)
            self._period_start_s, self._period_arrivals = now, 0
            handler = self.handler_time.copy()
            self.handler_time.reset()
            rejected_by = dict(sorted(self.pipeline.rejected.items()))
            samples, events = self.pipeline.samples, self.events_published
            ages = {"sample_age": self.sample_age.copy(), "onset_age": self.onset_age.copy()}
        rejected = sum(rejected_by.values())
        problems = [f"{rejected} samples rejected"] if rejected else []
        if isinstance(self.pipeline, AwaitingModel):
            problems.insert(0, "waiting for a URDF on /robot_description")
        delivery = self._delivery_values(problems)
        if self.hot_path.priority_error:
            problems.append(self.hot_path.priority_error)
        status.level = DiagnosticStatus.WARN if problems else DiagnosticStatus.OK
        status.message = "; ".join(problems) or "ok"
        values: dict[str, Any] = {
            "joint_states_rate_hz": f"{rate:.1f}", "samples": samples,
            "rejected_total": rejected, "events_published": events,
            "hot_path_scheduling": (
                f"SCHED_FIFO {self.hot_path.priority}"
                if self.hot_path.priority and not self.hot_path.priority_error else "normal"
            ),
        }  # fmt: skip
        # the handler's time in this period; the ages since start
        for key, hist, digits in (("latency", handler, 0), *((k, h, 1) for k, h in ages.items())):
            if key != "latency":
                values[f"{key}_count"] = hist.count
            for q in (50, 99):
                values[f"{key}_p{q}_us"] = f"{hist.percentile(q) * 1e6:.{digits}f}"
            values[f"{key}_max_us"] = f"{hist.max_s * 1e6:.{digits}f}"
        values.update({f"rejected_{k}": v for k, v in rejected_by.items()})
        values.update(delivery)
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)

    def _delivery_values(self, problems: list[str]) -> dict[str, Any]:
        """/joint_states received and lost on the way (publication sequence numbers), since
        start or ~/reset; a loss is a problem (WARN)."""
        if self.delivery is None:
            return {"joint_states_lost": "n/a (in-process)"}
        d = self.delivery
        publishers = self.count_publishers("/joint_states")
        if publishers > 1:
            lost: Any = f"unknown ({publishers} publishers)"
        else:
            lost = d.lost
            if d.lost:
                problems.append(
                    f"{d.lost} /joint_states samples lost before the estimator (a burst beyond "
                    f"queue_depth {self.values['queue_depth']}, or the network)"
                )
        return {"joint_states_received": d.received, "joint_states_lost": lost}

    def reconfigure(self, **changes: Any) -> None:
        """Set several parameters atomically (validated together), as the parameter service's
        set_parameters_atomically does; raise with the node's reason when refused."""
        result = self.set_parameters_atomically([Parameter(k, value=v) for k, v in changes.items()])
        if not result.successful:
            raise EstimatorError(result.reason)

    def detector_settings(self) -> DetectorSettings:
        if isinstance(self.pipeline, AwaitingModel):
            return observer_settings(self.values)
        return replace(self.pipeline.detector.default)


DESCRIPTION = (
    "Estimate joint torque from the impedance controller's position error, tau_hat = "
    "k_s (theta_d - theta_a) (eq. 1), and publish contact onsets (/contact, /collision), "
    "releases (/contact_release), the contact state per joint (~/state/<joint>) and "
    "/estimated_effort. Service ~/reset (std_srvs/Trigger)."
)


def main(args: list[str] | None = None) -> int:
    return run_node(NODE_NAME, DESCRIPTION, PARAMETERS, ContactEstimatorNode, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
