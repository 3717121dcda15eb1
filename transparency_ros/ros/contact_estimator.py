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
  crossed the threshold, frame_id = the link the joint moves when the URDF is known (else the
  joint), torque.z = tau_hat [N m], force.z = tau_hat /
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
from transparency_ros.core.setpoint_join import Paired, SetpointJoin, StateSample
from transparency_ros.ros import in_process
from transparency_ros.ros.conversions import stamp_to_ns
from transparency_ros.ros.estimator_params import (
    GAIN_PARAMS,
    LATCHED,
    NODE_NAME,
    PARAMETERS,
    detector_settings,
    load_calibration,
    observer_pipeline,
    observer_settings,
)
from transparency_ros.ros.hot_path import Delivery, HotPath
from transparency_ros.ros.params import (
    accept_integers_for_doubles,
    check_unknown,
    choice_error,
    declare,
    destroyed_if_refused,
    run_node,
)
from transparency_ros.ros.throttle import ThrottledWarning

GAP_NOTED_RAD = 1e-3  # a setpoint/command difference the diagnostics message mentions


@destroyed_if_refused
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
        # theta_d from the driver's setpoints, paired with the samples (position_error only)
        self.join: SetpointJoin | None = None
        if isinstance(self.pipeline, EstimatorPipeline) and self.values["use_setpoints"]:
            wait_s = self.values["setpoint_wait_s"]
            self.join = SetpointJoin(max_wait_s=wait_s)
            # samples waiting for setpoints while nothing arrives
            self.create_timer(max(wait_s / 2, 0.005), self._expire_waiting)
        self._missing_seen = 0  # setpoints missing at the last diagnostics
        self._frames: dict[str, str] = {}  # joint -> the link it moves (observer: from the URDF)
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
        self._warn = ThrottledWarning(self.get_logger())
        self._readers = {t: JointStateReader() for t in ("/joint_states", "/joint_setpoints")}
        self.hot_path = HotPath(self, priority=self.values["hot_path_priority"])
        self._leave_in_process: list[Any] = []
        self.delivery: Delivery | None = None  # what DDS delivered and lost (not in-process)
        streams = {"/joint_states": self._on_state_bytes}
        if self.join is not None:  # the setpoints first: they usually come first
            streams = {"/joint_setpoints": self._on_setpoint_bytes, **streams}
        depth = self.values["queue_depth"]
        for topic, handler in streams.items():
            if self.values["in_process"]:
                self._leave_in_process.append(in_process.subscribe(
                    self.context, topic, self.hot_path.guarded(handler)))  # fmt: skip
            else:
                sub = self.hot_path.subscribe(JointState, topic, depth, handler)
                if topic == "/joint_states":
                    self.delivery = self.hot_path.delivery(sub)
        if not self.values["in_process"]:
            self.hot_path.start()

    def destroy_node(self) -> None:
        for leave in self._leave_in_process:
            leave()
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
            self._frames.clear()
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
            with self.lock:  # (an empty position with efforts: a pure torque command)
                self.pipeline.command(*args, efforts=list(msg.effort))
        except SampleRejectedError as err:
            self._warn(f"rejected /joint_commands: {err}")

    def _decode(self, data: bytes, topic: str) -> JointStateFields | None:
        """Called with ``self.lock`` held (a reader keeps its stream's layout)."""
        try:
            return self._readers[topic](data)
        except CdrError as fast_error:
            try:  # what core.cdr does not read (big-endian CDR): rclpy's deserializer
                msg = deserialize_message(data, JointState)
            except Exception:  # noqa: BLE001 - any failure means the bytes are not a JointState
                self.pipeline.reject("undecodable", str(fast_error))
                self._warn(f"rejected {topic}: not a JointState ({fast_error})")
                return None
        stamp = msg.header.stamp
        return JointStateFields(
            stamp.sec, stamp.nanosec, msg.header.frame_id, list(msg.name),
            tuple(msg.position), tuple(msg.velocity), tuple(msg.effort),
        )  # fmt: skip

    def _on_state_bytes(self, data: bytes) -> None:
        started = time.perf_counter()
        with self.lock:
            sample = self._decode(data, "/joint_states")
            if sample is None:
                return
            self._period_arrivals += 1
            state = StateSample(
                sample.stamp_ns, sample.name, list(sample.position), list(sample.velocity)
            )
            now = time.monotonic()
            self._estimate(self.join.sample(state, now) if self.join else [Paired(state, None)])
            self.handler_time.add(time.perf_counter() - started)

    def _on_setpoint_bytes(self, data: bytes) -> None:
        """The driver's setpoints of a sample (``core.setpoint_join``): the samples they free."""
        with self.lock:
            setpoint = self._decode(data, "/joint_setpoints")
            if setpoint is None or self.join is None:
                return
            try:
                ready = self.join.setpoint(
                    setpoint.stamp_ns,
                    setpoint.name,
                    list(setpoint.position),
                    list(setpoint.velocity),
                    time.monotonic(),
                )
            except ValueError as err:
                self.pipeline.reject("bad_setpoint", str(err))
                self._warn(f"rejected /joint_setpoints: {err}")
                return
            self._estimate(ready)

    def _expire_waiting(self) -> None:
        """On the executor, not the hot path: release samples that waited while nothing
        arrived, and say what the join found out (logging is I/O)."""
        join = self.join
        if join is None:
            return
        if join.waiting:
            # a setpoint publisher in the graph, none heard yet: it is being matched
            expected = not join.active and self.count_publishers("/joint_setpoints") > 0
            with self.lock:
                join.expected = expected
                self._estimate(join.expire(time.monotonic()))
        if join.found_without or join.stopped:
            with self.lock:
                without, stopped = join.take_news()
            if without:
                self.get_logger().info(
                    f"no /joint_setpoints for {', '.join(without)} (a source without them): "
                    "theta_d from /joint_commands"
                )
            for joint in stopped:
                self.get_logger().warning(
                    f"/joint_setpoints stopped naming {joint}: theta_d from /joint_commands"
                )

    def _estimate(self, ready: list[Paired]) -> None:
        """Estimate and publish samples in order; called with ``self.lock`` held."""
        for paired in ready:
            state = paired.sample
            args = (state.stamp_ns, state.names, state.positions, state.velocities)
            try:
                if paired.setpoints is not None:  # (only a position_error pipeline pairs)
                    assert isinstance(self.pipeline, EstimatorPipeline)
                    estimates, events = self.pipeline.sample(*args, paired.setpoints)
                else:
                    estimates, events = self.pipeline.sample(*args)
            except SampleRejectedError as err:
                self._warn(f"rejected /joint_states: {err}")
                continue
            for event in events:  # first: a behavior waits for them
                self._publish_event(event, state.stamp_ns)
            sec, nanosec = stamps.split(state.stamp_ns)
            out = encode_joint_state(
                sec,
                nanosec,
                "",
                [e.joint for e in estimates],
                position=[e.error_rad for e in estimates],
                effort=[e.torque_nm for e in estimates],
            )
            # the age at the publish call, as the source's stamp is (delivery is after both)
            self.sample_age.add((time.time_ns() - state.stamp_ns) * 1e-9)
            self._estimate_pub.publish(out)

    def _frame(self, joint: str) -> str:
        """The frame_id of a joint's events: the link it moves when the URDF is known (a TF
        frame), else the joint's name."""
        pipeline = self.pipeline
        if isinstance(pipeline, ObserverPipeline):
            frame = self._frames.get(joint)
            if frame is None:
                frame = self._frames[joint] = pipeline.model.child_link(joint)
            return frame
        return joint

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
                self._frame(event.joint),
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
            if self.join is not None:
                self.join.reset()
                self._missing_seen = 0
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
            theta_d = self._theta_d_values()
        rejected = sum(rejected_by.values())
        problems = [f"{rejected} samples rejected"] if rejected else []
        missing = theta_d.get("setpoints_missing", 0) - self._missing_seen
        self._missing_seen += missing
        if missing:
            problems.append(
                f"{missing} samples without their /joint_setpoints: the nearest setpoint stood "
                "in (setpoints lost, or setpoint_wait_s too short)"
            )
        if isinstance(self.pipeline, AwaitingModel):
            problems.insert(0, "waiting for a URDF on /robot_description")
        delivery = self._delivery_values(problems)
        if self.hot_path.priority_error:
            problems.append(self.hot_path.priority_error)
        status.level = DiagnosticStatus.WARN if problems else DiagnosticStatus.OK
        notes = [theta_d.pop("note")] if "note" in theta_d else []
        status.message = "; ".join(problems + notes) or "ok"
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
        values.update(theta_d)
        values.update({f"rejected_{k}": v for k, v in rejected_by.items()})
        values.update(delivery)
        status.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(array)

    def _theta_d_values(self) -> dict[str, Any]:
        """Where theta_d came from, and the largest difference, at the latest samples, between
        the driver's setpoint and the latest /joint_commands (with ``self.lock`` held)."""
        pipeline, join = self.pipeline, self.join
        if not isinstance(pipeline, EstimatorPipeline):
            return {"theta_d_source": "/joint_commands efforts (momentum observer)"}
        values: dict[str, Any] = {
            "theta_d_source": "/joint_setpoints" if join and join.active else "/joint_commands",
            "samples_not_driven": pipeline.not_driven,
        }
        if join is not None:
            values.update(setpoints_matched=join.matched, setpoints_missing=join.missing,
                          setpoints_before_first=join.before_first,
                          samples_without_setpoints=join.unpaired_samples)  # fmt: skip
        gap, joint = max(((g, j) for j, g in pipeline.theta_d_gap.items()), default=(0.0, ""))
        values["theta_d_gap_max_rad"] = f"{gap:.4g}"
        if gap > GAP_NOTED_RAD:
            values["theta_d_gap_joint"] = joint
            values["note"] = (
                f"{joint}: the driver's theta_d differs from the last /joint_commands by "
                f"{gap:.3g} rad (clamped, held after its command timeout, or a command one of "
                "them missed); tau_hat uses the driver's"
            )
        return values

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
