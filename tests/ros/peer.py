"""rclpy peer for kumi's ROS 2 interop tests: a stock ROS 2 Kilted node (rclpy from PyPI) that
talks to kumi's nodes. Each subcommand runs one scenario and prints one JSON object on its last
line of stdout. Every wait has a deadline; the Rust tests also kill this process on timeout.

Run with ROS_DOMAIN_ID set to the domain of the node under test.
"""

import argparse
import faulthandler
import json
import math
import os
import sys
import threading
import time

import rclpy
import rclpy.executors
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import (Point, Pose, PoseStamped, PoseWithCovariance, Quaternion, Transform,
                               TransformStamped, Twist, TwistWithCovariance, Vector3)
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState
from std_msgs.msg import (Bool, Float64, Float64MultiArray, Header, MultiArrayDimension,
                          MultiArrayLayout, String)

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
DEFAULT = 10  # rclpy's default: reliable, volatile, keep last 10

TYPES = {
    "builtin_interfaces/Time": Time,
    "std_msgs/Header": Header,
    "std_msgs/Float64": Float64,
    "std_msgs/Float64MultiArray": Float64MultiArray,
    "std_msgs/MultiArrayLayout": MultiArrayLayout,
    "std_msgs/MultiArrayDimension": MultiArrayDimension,
    "std_msgs/String": String,
    "std_msgs/Bool": Bool,
    "geometry_msgs/Vector3": Vector3,
    "geometry_msgs/Point": Point,
    "geometry_msgs/Quaternion": Quaternion,
    "geometry_msgs/Pose": Pose,
    "geometry_msgs/PoseStamped": PoseStamped,
    "geometry_msgs/Twist": Twist,
    "geometry_msgs/Transform": Transform,
    "geometry_msgs/TransformStamped": TransformStamped,
    "geometry_msgs/PoseWithCovariance": PoseWithCovariance,
    "geometry_msgs/TwistWithCovariance": TwistWithCovariance,
    "sensor_msgs/JointState": JointState,
    "sensor_msgs/Imu": Imu,
    "nav_msgs/Odometry": Odometry,
    "rosgraph_msgs/Clock": Clock,
    "diagnostic_msgs/KeyValue": KeyValue,
    "diagnostic_msgs/DiagnosticStatus": DiagnosticStatus,
    "diagnostic_msgs/DiagnosticArray": DiagnosticArray,
}


_T0 = time.monotonic()


def note(text):
    """A progress line on stderr, seconds since start: a peer killed at its deadline shows where
    it was."""
    print(f"[peer {time.monotonic() - _T0:7.2f} s] {text}", file=sys.stderr, flush=True)


def to_dict(msg):
    """A message as plain JSON-able values, field by field (`byte` fields as integers)."""
    if hasattr(msg, "get_fields_and_field_types"):
        out = {}
        for f, ftype in msg.get_fields_and_field_types().items():
            v = getattr(msg, f)
            out[f] = v[0] if ftype == "octet" and isinstance(v, bytes) else to_dict(v)
        return out
    if isinstance(msg, (list, tuple)) or type(msg).__name__ in ("ndarray", "array"):
        return [to_dict(x) for x in msg]
    return msg


def from_dict(cls, values):
    """A message of type `cls` with the fields in `values` (nested dicts and lists)."""
    msg = cls()
    for field, ftype in msg.get_fields_and_field_types().items():
        if field not in values:
            continue
        v = values[field]
        current = getattr(msg, field)
        if hasattr(current, "get_fields_and_field_types"):
            setattr(msg, field, from_dict(type(current), v))
        elif ftype.startswith("sequence<") and "/" in ftype:
            inner = ftype[len("sequence<"):-1]
            pkg, name = inner.split("/")
            setattr(msg, field, [from_dict(TYPES[f"{pkg}/{name}"], x) for x in v])
        elif ftype == "octet":
            setattr(msg, field, bytes([v]))
        else:
            setattr(msg, field, v)
    return msg


class Peer(Node):
    def __init__(self):
        super().__init__("kumi_test_peer")
        self.latest = {}

    def listen(self, cls, topic, key=None, qos=DEFAULT):
        key = key or topic

        def store(m):
            self.latest[key] = m
            self.latest.setdefault(key + "#count", 0)
            self.latest[key + "#count"] += 1
            self.latest.setdefault(key + "#first", m)

        return self.create_subscription(cls, topic, store, qos)

    def spin_until(self, done, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            rclpy.spin_once(self, timeout_sec=0.02)
            if done():
                return True
        return False

    def wait_for_new(self, key, timeout, predicate=lambda m: True):
        before = self.latest.get(key + "#count", 0)
        ok = self.spin_until(lambda: self.latest.get(key + "#count", 0) > before and predicate(self.latest[key]), timeout)
        return self.latest.get(key) if ok else None


def stamp(msg):
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def diag_values(peer, timeout=4.0):
    msg = peer.wait_for_new("/diagnostics", timeout)
    if msg is None:
        return None
    status = to_dict(msg.status[0])
    return {kv["key"]: kv["value"] for kv in status["values"]} | {"_level": status["level"], "_message": status["message"]}


def latest_diagnostics(peer):
    """Subscribes to /diagnostics; returns the dict it keeps filled: status name -> its latest
    key/value pairs."""
    statuses = {}

    def on_diag(m):
        for status in m.status:
            statuses[status.name] = {kv.key: kv.value for kv in status.values}

    peer.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DEFAULT)
    return statuses


def cmd_observe(args, peer):
    arms, wheels = args.arms.split(","), [w for w in args.wheels.split(",") if w]
    r = args.robot
    for m in arms + wheels:
        peer.listen(JointState, f"/{r}/{m}/joint_states")
    peer.listen(Odometry, f"/{r}/odom")
    peer.listen(Imu, f"/{r}/imu")
    peer.listen(Clock, "/clock")
    peer.listen(DiagnosticArray, "/diagnostics")
    peer.listen(String, f"/{r}/robot_description", qos=LATCHED)
    peer.listen(Clock, f"/{r}/clock")
    wanted = [f"/{r}/{m}/joint_states" for m in arms + wheels] + [f"/{r}/odom", f"/{r}/imu", "/clock", f"/{r}/clock", "/diagnostics", f"/{r}/robot_description"]
    peer.spin_until(lambda: all(k in peer.latest for k in wanted), args.timeout)
    out = {"received": {k: k in peer.latest for k in wanted}}
    out["nodes"] = [f"{ns.rstrip('/')}/{n}" for n, ns in peer.get_node_names_and_namespaces()]
    out["topic_types"] = {t: ts for t, ts in peer.get_topic_names_and_types()}
    out["joint_states"] = {}
    for m in arms + wheels:
        js = peer.latest.get(f"/{r}/{m}/joint_states")
        if js:
            out["joint_states"][m] = {"name": list(js.name), "position": list(js.position), "velocity": list(js.velocity)}
    odom = peer.latest.get(f"/{r}/odom")
    if odom:
        p = odom.pose.pose.position
        q = odom.pose.pose.orientation
        out["odom"] = {"frame": odom.header.frame_id, "child": odom.child_frame_id, "position": [p.x, p.y, p.z], "quat_norm": math.sqrt(q.x**2 + q.y**2 + q.z**2 + q.w**2), "covariance_len": len(odom.pose.covariance)}
    imu = peer.latest.get(f"/{r}/imu")
    if imu:
        a = imu.linear_acceleration
        out["imu"] = {"frame": imu.header.frame_id, "accel": [a.x, a.y, a.z]}
    clock = peer.latest.get("/clock")
    if clock:
        out["clock_s"] = clock.clock.sec + clock.clock.nanosec * 1e-9
    desc = peer.latest.get(f"/{r}/robot_description")
    out["description_chars"] = len(desc.data) if desc else 0
    out["description_head"] = desc.data[:200] if desc else ""
    d = peer.latest.get("/diagnostics")
    if d:
        out["diagnostics_name"] = d.status[0].name
    return out


def cmd_drive(args, peer):
    r = args.robot
    js_topic = f"/{r}/{args.arm}/joint_states"
    peer.listen(JointState, js_topic)
    peer.listen(Odometry, f"/{r}/odom")
    inc = peer.create_publisher(Float64MultiArray, f"/{r}/{args.arm}/joint_increments", DEFAULT)
    wheels = [peer.create_publisher(Float64, f"/{r}/{w}/wheel_velocity", DEFAULT) for w in (args.wheels or args.wheel).split(",")]
    out = {}
    if not peer.spin_until(lambda: js_topic in peer.latest and f"/{r}/odom" in peer.latest, args.timeout):
        return {"error": "no joint states or odometry"}
    # Wait until a subscriber for our increments exists (discovery), then send one increment.
    peer.spin_until(lambda: inc.get_subscription_count() > 0 and all(w.get_subscription_count() > 0 for w in wheels), args.timeout)
    q0 = list(peer.latest[js_topic].position)
    msg = Float64MultiArray()
    msg.data = [args.increment if i == args.joint else 0.0 for i in range(len(q0))]
    for _ in range(args.count):  # each within one control step's reach
        inc.publish(msg)
        peer.spin_until(lambda: False, 0.05)
    peer.spin_until(lambda: False, 1.0)
    out["q0"] = q0
    out["q1"] = list(peer.latest[js_topic].position)
    # Wheels: keep commanding (commands older than 0.5 s are dropped), watch the base move.
    x0 = peer.latest[f"/{r}/odom"].pose.pose.position
    q = peer.latest[f"/{r}/odom"].pose.pose.orientation
    yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    deadline = time.monotonic() + args.drive_seconds
    while time.monotonic() < deadline:
        for w in wheels:
            w.publish(Float64(data=args.wheel_velocity))
        peer.spin_until(lambda: False, 0.1)
    x1 = peer.latest[f"/{r}/odom"].pose.pose.position
    out["base_moved_m"] = math.dist([x0.x, x0.y], [x1.x, x1.y])
    # Along the base's x axis as it was at the start.
    out["base_forward_m"] = (x1.x - x0.x) * math.cos(yaw) + (x1.y - x0.y) * math.sin(yaw)
    return out


def cmd_late(args, peer):
    peer.listen(String, f"/{args.robot}/robot_description", qos=LATCHED)
    peer.spin_until(lambda: f"/{args.robot}/robot_description" in peer.latest, args.timeout)
    d = peer.latest.get(f"/{args.robot}/robot_description")
    return {"description_chars": len(d.data) if d else 0, "starts_with": d.data[:40] if d else ""}


def cmd_roundtrip(args, peer):
    samples = json.load(open(args.samples))
    pubs, echoes, got = {}, {}, {}
    for tname, values in samples.items():
        cls = TYPES[tname]
        key = tname.replace("/", "_")
        pubs[tname] = (peer.create_publisher(cls, f"/kumi_rt/py2rs/{key}", DEFAULT), from_dict(cls, values))
        echoes[tname] = peer.create_publisher(cls, f"/kumi_rt/py_echo/{key}", DEFAULT)

        def on(m, tname=tname):
            got[tname] = to_dict(m)
            echoes[tname].publish(m)

        peer.create_subscription(cls, f"/kumi_rt/rs2py/{key}", on, DEFAULT)
    deadline = time.monotonic() + args.timeout
    while time.monotonic() < deadline and len(got) < len(samples):
        for pub, msg in pubs.values():
            pub.publish(msg)
        peer.spin_until(lambda: False, 0.1)
    # Keep publishing and echoing a little longer so the Rust side sees everything.
    linger = time.monotonic() + args.linger
    while time.monotonic() < linger:
        for pub, msg in pubs.values():
            pub.publish(msg)
        peer.spin_until(lambda: False, 0.1)
    return {"received_from_rust": {t: got.get(t) for t in samples}, "equal": {t: got.get(t) == json.loads(json.dumps(samples[t])) for t in samples}}


def controller_increment(k, j, seed):
    """The deterministic command sequence of the lockstep test [rad]."""
    return 0.02 * math.sin(0.1 * k * (j + 1) + seed)


def arm_io(args, peer):
    """Listens to an arm's joint states and publishes its increments; waits for the bridge.
    Returns (joint-state topic, increments publisher), or None if no bridge answered."""
    js_topic = f"/{args.robot}/{args.arm}/joint_states"
    peer.listen(JointState, js_topic)
    inc = peer.create_publisher(Float64MultiArray, f"/{args.robot}/{args.arm}/joint_increments", DEFAULT)
    if not peer.spin_until(lambda: js_topic in peer.latest and inc.get_subscription_count() > 0, args.timeout):
        return None
    return js_topic, inc


def cmd_lockstep(args, peer):
    io = arm_io(args, peer)
    if io is None:
        return {"error": "bridge not found"}
    js_topic, inc = io
    trajectory, last_stamp = [], None
    t0 = None
    deadline = time.monotonic() + args.timeout
    while len(trajectory) < args.steps and time.monotonic() < deadline:
        js = peer.latest[js_topic]
        s = stamp(js)
        if s != last_stamp:
            last_stamp = s
            trajectory.append({"t": s, "q": list(js.position)})
            if t0 is None:
                t0 = time.monotonic()
            k = len(trajectory)
            msg = Float64MultiArray()
            msg.data = [controller_increment(k, j, args.seed) for j in range(len(js.position))]
            inc.publish(msg)
        rclpy.spin_once(peer, timeout_sec=0.05)
    wall = time.monotonic() - (t0 or time.monotonic())
    return {"trajectory": trajectory, "steps_per_s": (len(trajectory) - 1) / wall if wall > 0 else 0.0}


def goal_msg(values, frame=""):
    x, y, z, qw, qx, qy, qz = values
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position = Point(x=x, y=y, z=z)
    msg.pose.orientation = Quaternion(w=qw, x=qx, y=qy, z=qz)
    return msg


RESEND_S = 0.1  # wall seconds between resends of a goal not yet acted on
MOVED_M = 1e-3  # the tool moved this far [m]: its goal arrived


def cmd_reach(args, peer):
    """Sends one goal to an arm node running against a lockstep bridge; reports the tool pose
    after --drive-seconds of simulated time."""
    r, a = args.robot, args.arm
    ee_topic = f"/{r}/{a}/ee_pose"
    peer.listen(PoseStamped, ee_topic)
    peer.listen(Clock, f"/{r}/clock")
    goal = peer.create_publisher(PoseStamped, f"/{r}/{a}/goal_pose", DEFAULT)
    # --record: every increment the arm node sends from the goal on, for hold smoothness (a
    # history deep enough that none is dropped while this peer is busy). The node sends zeros
    # while it holds without a goal: one received says its writer has matched this reader.
    increments = []
    recorder = args.record and peer.create_subscription(
        Float64MultiArray, f"/{r}/{a}/joint_increments", lambda m: increments.append(list(m.data)),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    if not peer.spin_until(lambda: ee_topic in peer.latest and (args.wall or f"/{r}/clock" in peer.latest) and goal.get_subscription_count() > 0
                           and (not recorder or len(increments) > 0), args.timeout):
        return {"error": "arm node or bridge not found"}
    if args.wall:  # on hardware there is no /clock: wall time
        sim = time.monotonic
    else:
        sim = lambda: peer.latest[f"/{r}/clock"].clock.sec + peer.latest[f"/{r}/clock"].clock.nanosec * 1e-9
    if args.disturb:
        # Another publisher moves joint2 (issue 10, finding 1; within the skill's start range of
        # +-0.5 rad), and a wild increment arrives: the bridge owns the targets, so neither may
        # throw the arm node off its later goals.
        jset = peer.create_publisher(JointState, f"/{r}/{a}/joint_set", DEFAULT)
        inc = peer.create_publisher(Float64MultiArray, f"/{r}/{a}/joint_increments", DEFAULT)
        peer.spin_until(lambda: jset.get_subscription_count() > 0 and inc.get_subscription_count() > 0, args.timeout)
        jset.publish(JointState(name=["joint2"], position=[0.45]))
        inc.publish(Float64MultiArray(data=[1e308] * 7))
        t0 = sim()
        peer.spin_until(lambda: sim() >= t0 + 2.0, args.timeout)
    start, wall = sim(), time.monotonic()
    target = [float(v) for v in args.goal.split(",")]
    p0 = peer.latest[ee_topic].pose.position
    msg = goal_msg(target, args.frame)
    increments.clear()
    goal.publish(msg)
    # The publisher has matched the node's reader, but the node's reader may not yet have
    # matched this writer (DDS discovery runs both ways at its own pace), and a sample sent in
    # that gap is lost. Resend the same goal (the node takes it again, unchanged) every RESEND_S
    # until the tool moves MOVED_M, which it does only once a goal arrived.
    resend = {"at": time.monotonic() + RESEND_S, "sends": 1}

    def done():
        p = peer.latest[ee_topic].pose.position
        if math.dist([p.x, p.y, p.z], [p0.x, p0.y, p0.z]) < MOVED_M and time.monotonic() >= resend["at"]:
            goal.publish(msg)
            resend["at"] = time.monotonic() + RESEND_S
            resend["sends"] += 1
        if sim() >= start + args.drive_seconds:
            return True
        return args.within > 0 and math.dist([p.x, p.y, p.z], target[:3]) < args.within

    peer.spin_until(done, args.timeout)
    ee = peer.latest[ee_topic]
    p, o = ee.pose.position, ee.pose.orientation
    return {"start": start, "end": sim(), "wall_s": time.monotonic() - wall, "start_position": [p0.x, p0.y, p0.z],
            "position": [p.x, p.y, p.z], "goal_sends": resend["sends"],
            "orientation": [o.w, o.x, o.y, o.z], "frame": ee.header.frame_id,
            "increments": increments}


def yaw_of(o):
    """Heading of a pose's x axis about z [rad]."""
    return math.atan2(2.0 * (o.w * o.z + o.x * o.y), 1.0 - 2.0 * (o.y * o.y + o.z * o.z))


def cmd_target(args, peer):
    """Sends the robot a target for its tool (--goal x,y,z,yaw in <robot>/odom) through the
    whole-body node, as a user would; records the tool pose it reports (/<robot>/tool_pose) for
    --drive-seconds of simulated time. With --disturb, a NaN target and one in a wrong frame go
    first: both must be refused (and counted) and the real one still reached."""
    r = args.robot
    tool_topic = f"/{r}/tool_pose"
    trajectory = []

    def on_tool(m):
        p = m.pose.position
        trajectory.append([stamp(m), p.x, p.y, p.z, yaw_of(m.pose.orientation)])

    peer.create_subscription(PoseStamped, tool_topic, on_tool, DEFAULT)
    peer.listen(PoseStamped, tool_topic)
    peer.listen(Clock, f"/{r}/clock")
    statuses = latest_diagnostics(peer)
    target = peer.create_publisher(PoseStamped, f"/{r}/goal_pose", DEFAULT)
    if not peer.spin_until(lambda: (args.wall or f"/{r}/clock" in peer.latest) and target.get_subscription_count() > 0, args.timeout):
        return {"error": "whole-body node or bridge not found"}
    if args.wall:  # on hardware there is no /clock: wall time
        sim = time.monotonic
    else:
        sim = lambda: peer.latest[f"/{r}/clock"].clock.sec + peer.latest[f"/{r}/clock"].clock.nanosec * 1e-9
    x, y, z, yaw = [float(v) for v in args.goal.split(",")]
    msg = goal_msg([x, y, z, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)], args.frame or f"{r}/odom")
    if args.disturb:
        bad = goal_msg([float("nan"), y, z, 1.0, 0.0, 0.0, 0.0], f"{r}/odom")
        target.publish(bad)
        target.publish(goal_msg([x, y, z, 1.0, 0.0, 0.0, 0.0], "world"))
        peer.spin_until(lambda: False, 0.5)
    trajectory.clear()
    start, wall = sim(), time.monotonic()
    target.publish(msg)
    peer.spin_until(lambda: sim() >= start + args.drive_seconds, args.timeout)
    # Every node reports once per wall second: wait for a report from each one heard so far,
    # the whole-body node and every status named in --expect, sent after the drive (not one
    # from before or during it). A loaded machine can delay a report by seconds, so the wait is
    # long; it ends as soon as all have come.
    name = f"kumi whole-body node: {r}"
    expected = {e for e in args.expect.split(",") if e}
    wanted = set(statuses) | {name} | expected
    statuses.clear()
    peer.spin_until(lambda: wanted <= set(statuses), 15.0)
    diagnostics = statuses.get(name, {})
    end = trajectory[-1] if trajectory else None
    return {"start": start, "end": sim(), "wall_s": time.monotonic() - wall,
            "trajectory": trajectory, "diagnostics": diagnostics, "all_diagnostics": statuses,
            "missing_diagnostics": sorted(wanted - set(statuses)),
            "position_error_m": math.dist(end[1:4], [x, y, z]) if end else None,
            "yaw_error_rad": abs((yaw - end[4] + math.pi) % (2 * math.pi) - math.pi) if end else None}


def cmd_fakelimb(args, peer):
    """A fake Motion Stack limb (MoonBot's driver) at --frame (its namespace, `/leg7`) with the
    joints --arms (comma-separated): takes absolute targets on `joint_set` (positions by name;
    velocities for wheels), moves each joint toward its target at 0.05 rad per 30 Hz tick, and
    publishes `joint_read` as Motion Stack does: once when a subscriber appears, then only when a
    joint moved by 1e-3 rad or more (its encoder's resolution) since the last message, or came to
    rest. Position joints follow their targets at once (an ideal servo: the test must not depend
    on how fast this Python loop runs on a loaded machine); wheels turn at their velocities.
    Runs --drive-seconds, then leaves cleanly."""
    ns = args.frame
    names = args.arms.split(",")
    start = [float(v) for v in args.samples.split(",")] if args.samples else [0.0] * len(names)
    q = dict(zip(names, start))  # --samples: the joints' start angles
    target = dict(q)
    sent = dict(q)
    counts = {"joint_set": 0, "joint_read": 0}
    velocity = {n: 0.0 for n in names}  # wheels: commanded joint velocities [rad/s]
    wheels = set()
    largest = {}
    read = peer.create_publisher(JointState, f"{ns}/joint_read", DEFAULT)

    def on_set(m):
        counts["joint_set"] += 1
        for i, n in enumerate(m.name):
            if n in target and i < len(m.position) and math.isfinite(m.position[i]):
                target[n] = m.position[i]
            if n in velocity and i < len(m.velocity) and math.isfinite(m.velocity[i]):
                velocity[n] = m.velocity[i]
                wheels.add(n)
                if abs(m.velocity[i]) > abs(largest.get(n, 0.0)):
                    largest[n] = m.velocity[i]

    peer.create_subscription(JointState, f"{ns}/joint_set", on_set, DEFAULT)

    moved = {n: 0.0 for n in names}

    def publish():
        read.publish(JointState(name=names, position=[q[n] for n in names], velocity=[moved[n] * 30.0 for n in names]))
        sent.update(q)
        counts["joint_read"] += 1

    end = time.monotonic() + args.drive_seconds
    # Its first reading once someone listens (a reading published before the node subscribed
    # would be lost, as it is with Motion Stack's volatile joint_read).
    peer.spin_until(lambda: read.get_subscription_count() > 0, args.drive_seconds)
    note(f"{ns}/joint_read has {read.get_subscription_count()} subscriber(s)")
    peer.spin_until(lambda: False, 0.5)
    next_tick = time.monotonic()
    longest_quiet, last_read = 0.0, time.monotonic()
    publish()
    while time.monotonic() < end:
        rclpy.spin_once(peer, timeout_sec=0.005)
        if time.monotonic() < next_tick:
            continue
        next_tick += 1.0 / 30.0
        came_to_rest = False
        for n in names:
            before = q[n]
            if n in wheels:
                q[n] += velocity[n] / 30.0
                target[n] = q[n]
            else:
                q[n] = target[n]
            came_to_rest |= moved[n] != 0.0 and q[n] == before
            moved[n] = q[n] - before
        if came_to_rest or any(abs(q[n] - sent[n]) >= 1e-3 for n in names):
            longest_quiet = max(longest_quiet, time.monotonic() - last_read)
            last_read = time.monotonic()
            publish()
    longest_quiet = max(longest_quiet, time.monotonic() - last_read)
    return {"counts": counts, "longest_quiet_s": longest_quiet, "position": [q[n] for n in names],
            "largest_velocity": largest, "last_velocity": {n: velocity[n] for n in wheels}}


def cmd_fakeodom(args, peer):
    """A base that does not move, as a driver reports it: nav_msgs/Odometry at 30 Hz on --frame's
    topic (`/odom`), frame `odom`, stamped with wall time, for --drive-seconds."""
    pub = peer.create_publisher(Odometry, args.frame, DEFAULT)
    end = time.monotonic() + args.drive_seconds
    n = 0
    while time.monotonic() < end:
        m = Odometry()
        now = time.time()
        m.header.stamp.sec, m.header.stamp.nanosec = int(now), int((now % 1) * 1e9)
        m.header.frame_id = "odom"
        m.child_frame_id = "base"
        m.pose.pose.orientation.w = 1.0
        pub.publish(m)
        n += 1
        peer.spin_until(lambda: False, 1.0 / 30.0)
    return {"published": n}


def cmd_diagnostics(args, peer):
    """Every /diagnostics status heard within --drive-seconds: name -> its latest key/values
    (with `message` and `level`)."""
    statuses = {}

    def on_diag(m):
        for status in m.status:
            values = {kv.key: kv.value for kv in status.values}
            values["message"] = status.message
            values["level"] = int.from_bytes(status.level, "little") if isinstance(status.level, bytes) else int(status.level)
            statuses[status.name] = values

    peer.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DEFAULT)
    peer.spin_until(lambda: False, args.drive_seconds)
    return statuses


def cmd_flood(args, peer):
    """Issue 10's flood: --count goals as fast as rclpy sends them (random, within 5 cm of
    --goal), then 1 MB payloads on every topic the arm node and the bridge subscribe to (junk
    bytes, and well-formed messages of 1 MB; /clock's is short), then --goal itself: reports the tool pose after
    --drive-seconds of sim time and both nodes' diagnostics."""
    import random
    r, a = args.robot, args.arm
    ee_topic = f"/{r}/{a}/ee_pose"
    peer.listen(PoseStamped, ee_topic)  # not /clock: this peer sends junk there
    statuses = latest_diagnostics(peer)
    goal = peer.create_publisher(PoseStamped, f"/{r}/{a}/goal_pose", DEFAULT)
    states = peer.create_publisher(JointState, f"/{r}/{a}/joint_states", DEFAULT)
    clock = peer.create_publisher(Clock, f"/{r}/clock", DEFAULT)
    jset = peer.create_publisher(JointState, f"/{r}/{a}/joint_set", DEFAULT)
    inc = peer.create_publisher(Float64MultiArray, f"/{r}/{a}/joint_increments", DEFAULT)
    pubs = (goal, states, clock, jset, inc)
    if not peer.spin_until(lambda: ee_topic in peer.latest and all(p.get_subscription_count() > 0 for p in pubs), args.timeout):
        return {"error": "arm node or bridge not found"}
    target = [float(v) for v in args.goal.split(",")]
    rng = random.Random(int(args.seed))
    t = time.monotonic()
    for _ in range(args.count):
        jitter = [v + rng.uniform(-0.05, 0.05) for v in target[:3]]
        goal.publish(goal_msg(jitter + target[3:], args.frame))
    goals_s = time.monotonic() - t
    junk = bytes([0, 1, 0, 0]) + bytes([0x41]) * (1 << 20)
    big_names = ["joint%d" % (k % 7 + 1) for k in range(1 << 14)]
    big = [
        (goal, goal_msg(target, "x" * (1 << 20))),
        (states, JointState(name=big_names, position=[0.0] * len(big_names), velocity=[0.0] * len(big_names))),
        (jset, JointState(name=big_names, position=[0.0] * len(big_names))),
        (inc, Float64MultiArray(data=[0.0] * (1 << 17))),
    ]
    # Fast DDS itself refuses a write now and then while its reliable history still holds
    # unacknowledged samples of the burst ("cannot publish data"): such a write is retried.
    retries = 0

    def send(p, m):
        nonlocal retries
        for _ in range(20):
            try:
                p.publish(m)
                return
            except Exception:  # rclpy's RCLError
                retries += 1
                peer.spin_until(lambda: False, 0.25)
        raise RuntimeError(f"Fast DDS refused a payload of {len(m) if isinstance(m, bytes) else type(m).__name__} on {p.topic_name} 20 times")

    peer.spin_until(lambda: False, 0.5)
    t = time.monotonic()
    # Fast DDS will not send more than a bounded type's size (rosgraph_msgs/Clock: 8 bytes), so
    # /clock gets a payload cut short instead (4 bytes: any 8 would be a valid Clock).
    for p in pubs:
        send(p, bytes([0, 1, 0, 0]) + bytes([0x41]) * 4 if p is clock else junk)
    for p, m in big:
        send(p, m)
    peer.spin_until(lambda: False, 1.0)
    payload_s = time.monotonic() - t
    goal.publish(goal_msg(target, args.frame))
    peer.spin_until(lambda: False, args.drive_seconds)
    p = peer.latest[ee_topic].pose.position
    peer.spin_until(lambda: False, 1.5)
    return {"goals_s": goals_s, "payload_s": payload_s, "sender_retries": retries, "position": [p.x, p.y, p.z], "diagnostics": statuses}


def cmd_watch(args, peer):
    """Watches a robot for --drive-seconds of wall time: how far /clock moved, the bridge's last
    diagnostics (the largest stale_holds and lockstep_timeouts seen, every lockstep_silent
    value), and the arm's joint speeds at the end."""
    r, a = args.robot, args.arm
    js_topic = f"/{r}/{a}/joint_states"
    peer.listen(JointState, js_topic)
    peer.listen(Clock, f"/{r}/clock")
    silent, holds, timeouts, node = set(), 0, 0, {"stale_holds": 0, "messages": []}

    def on_diag(m):
        nonlocal holds, timeouts
        for status in m.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name.startswith("kumi arm node"):
                node["stale_holds"] = max(node["stale_holds"], int(values["stale_holds"]))
                node["messages"].append(status.message)
                continue
            holds = max(holds, int(values.get("stale_holds", 0)))
            timeouts = max(timeouts, int(values.get("lockstep_timeouts", 0)))
            silent.update(v for v in values.get("lockstep_silent", "").split(",") if v)

    peer.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DEFAULT)
    if not peer.spin_until(lambda: f"/{r}/clock" in peer.latest and js_topic in peer.latest, args.timeout):
        return {"error": "no bridge"}
    sim = lambda: peer.latest[f"/{r}/clock"].clock.sec + peer.latest[f"/{r}/clock"].clock.nanosec * 1e-9
    start = sim()
    peer.spin_until(lambda: False, args.drive_seconds)
    return {"clock_start": start, "clock_end": sim(), "stale_holds": holds, "lockstep_timeouts": timeouts,
            "lockstep_silent": sorted(silent), "max_speed": max(abs(v) for v in peer.latest[js_topic].velocity),
            "node": node}


def cmd_malformed(args, peer):
    """Sends hand-broken CDR (issue 10, finding 3) to the arm node and the bridge as raw bytes
    (rclpy publishes bytes as they are): a goal whose frame_id length is 0, a goal whose
    frame_id lacks its NUL, a JointState missing its last byte, a Float64MultiArray whose label
    length is 0. Reports the joint positions before and after and both nodes' diagnostics."""
    from rclpy.serialization import serialize_message
    r, a = args.robot, args.arm
    js_topic = f"/{r}/{a}/joint_states"
    peer.listen(JointState, js_topic)
    statuses = latest_diagnostics(peer)
    goal = peer.create_publisher(PoseStamped, f"/{r}/{a}/goal_pose", DEFAULT)
    jset = peer.create_publisher(JointState, f"/{r}/{a}/joint_set", DEFAULT)
    inc = peer.create_publisher(Float64MultiArray, f"/{r}/{a}/joint_increments", DEFAULT)
    if not peer.spin_until(lambda: js_topic in peer.latest and all(p.get_subscription_count() > 0 for p in (goal, jset, inc)), args.timeout):
        return {"error": "bridge or arm node not found"}
    peer.spin_until(lambda: False, 1.0)
    before = list(peer.latest[js_topic].position)

    good = goal_msg([0.35, 0.1, 1.0, 1.0, 0.0, 0.0, 0.0], f"{r}/{a}/base")
    raw = bytearray(serialize_message(good))
    # Encapsulation (4) + stamp (8), then frame_id's length at byte 12.
    zero_length = bytearray(raw); zero_length[12:16] = (0).to_bytes(4, "little")
    no_nul = bytearray(raw); n = int.from_bytes(raw[12:16], "little"); no_nul[16 + n - 1] = ord("x")
    js = JointState(name=["joint1"], position=[0.3])
    cut = serialize_message(js)[:-1]
    arr = Float64MultiArray(data=[0.05] + [0.0] * 6)
    arr.layout.dim = [MultiArrayDimension(label="x", size=7, stride=7)]
    label = bytearray(serialize_message(arr)); label[8:12] = (0).to_bytes(4, "little")
    for _ in range(3):
        goal.publish(bytes(zero_length)); goal.publish(bytes(no_nul))
        jset.publish(bytes(cut)); inc.publish(bytes(label))
        peer.spin_until(lambda: False, 0.2)
    peer.spin_until(lambda: False, 2.0)
    return {"before": before, "after": list(peer.latest[js_topic].position), "diagnostics": statuses}


def cmd_zerobyte(args, peer):
    """Issue 10, finding 4: one 0-byte sample, then one valid goal; reports how long the arm
    node took to accept the goal (from its diagnostics), or null."""
    r, a = args.robot, args.arm
    accepted = {"n": 0}

    def on_diag(m):
        for status in m.status:
            if status.name == f"kumi arm node: {r}/{a}":
                accepted["n"] = int({kv.key: kv.value for kv in status.values}["goals_accepted"])

    peer.create_subscription(DiagnosticArray, "/diagnostics", on_diag, DEFAULT)
    goal = peer.create_publisher(PoseStamped, f"/{r}/{a}/goal_pose", DEFAULT)
    if not peer.spin_until(lambda: goal.get_subscription_count() > 0, args.timeout):
        return {"error": "arm node not found"}
    peer.spin_until(lambda: False, 1.0)
    goal.publish(b"")
    goal.publish(goal_msg([0.35, 0.1, 1.0, 1.0, 0.0, 0.0, 0.0], f"{r}/{a}/base"))
    t = time.monotonic()
    ok = peer.spin_until(lambda: accepted["n"] > 0, args.drive_seconds)
    return {"accepted_after_s": time.monotonic() - t if ok else None}


def cmd_rosout(args, peer):
    """Listens on /rosout (as rcl publishes it: transient local, depth 1000) for
    --drive-seconds, after sending one goal in a frame the arm node does not know (a WARN)."""
    from rcl_interfaces.msg import Log
    records = []
    qos = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
    peer.create_subscription(Log, "/rosout", lambda m: records.append({"name": m.name, "level": m.level, "msg": m.msg}), qos)
    goal = peer.create_publisher(PoseStamped, f"/{args.robot}/{args.arm}/goal_pose", DEFAULT)
    peer.spin_until(lambda: goal.get_subscription_count() > 0, args.timeout)
    peer.spin_until(lambda: False, 1.0)
    goal.publish(goal_msg([0.35, 0.1, 1.0, 1.0, 0.0, 0.0, 0.0], "map"))
    peer.spin_until(lambda: False, args.drive_seconds)
    return {"records": records}


def cmd_armnode(args, peer):
    """Plays the robot for an arm node (wall time, no /clock): publishes joint states at 30 Hz
    and goals, and records what the node commands."""
    r, a = args.robot, args.arm
    inc_topic = f"/{r}/{a}/joint_increments"
    peer.listen(Float64MultiArray, inc_topic)
    js = peer.create_publisher(JointState, f"/{r}/{a}/joint_states", DEFAULT)
    goal = peer.create_publisher(PoseStamped, f"/{r}/{a}/goal_pose", DEFAULT)
    names = [f"{a}/joint{i}" for i in range(1, 8)]
    q = [0.1, 0.3, -0.2, 0.5, 0.0, 0.2, 0.1]
    state = {"publish": True, "names": names}

    def integrate(m):
        # A kinematic robot: the joints go where the increments send them.
        if len(m.data) == len(q):
            for i, d in enumerate(m.data):
                q[i] += d

    peer.create_subscription(Float64MultiArray, inc_topic, integrate, DEFAULT)

    def send_state():
        if state["publish"]:
            m = JointState()
            m.name = state["names"]
            m.position = q[:len(state["names"])]
            m.velocity = [0.0] * len(state["names"])
            js.publish(m)

    peer.create_timer(1.0 / 30.0, send_state)
    if not peer.spin_until(lambda: inc_topic in peer.latest and goal.get_subscription_count() > 0, args.timeout):
        return {"error": "arm node not found"}

    def phase(seconds):
        """Increments seen over `seconds`: the largest magnitude and how many messages."""
        seen = []
        deadline = time.monotonic() + seconds
        last = None
        while time.monotonic() < deadline:
            rclpy.spin_once(peer, timeout_sec=0.01)
            m = peer.latest.get(inc_topic)
            if m is not None and peer.latest[inc_topic + "#count"] != last:
                last = peer.latest[inc_topic + "#count"]
                seen.append(max(abs(v) for v in m.data) if m.data else -1.0)
        # Only the second half counts: the first lets the node catch up.
        tail = seen[len(seen) // 2:]
        return {"messages": len(seen), "max_abs": max(tail) if tail else None}

    good = [0.4, 0.1, 1.0, 1.0, 0.0, 0.0, 0.0]
    out = {"no_goal": phase(1.0)}
    bad = {
        "nan": goal_msg([float("nan"), 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]),
        "zero_quaternion": goal_msg([0.4, 0.1, 1.0, 0.0, 0.0, 0.0, 0.0]),
        "unknown_frame": goal_msg(good, "map"),
        "out_of_reach": goal_msg([5.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0]),
    }
    for kind, msg in bad.items():
        goal.publish(msg)
        out["bad_" + kind] = phase(0.6)
    goal.publish(goal_msg([good[0], good[1], good[2], 1.02, 0.0, 0.0, 0.0]))  # near-unit: normalised
    out["good_goal"] = phase(1.0)
    goal.publish(bad["nan"])
    out["nan_after_good"] = phase(1.0)
    state["names"] = names[:6]  # wrong size: one joint missing
    out["missing_joint"] = phase(1.0)
    state["names"] = names
    out["recovered"] = phase(1.0)
    state["publish"] = False
    out["stale"] = phase(1.0)
    return out


def cmd_badinput(args, peer):
    r = args.robot
    js_topic = f"/{r}/{args.arm}/joint_states"
    peer.listen(JointState, js_topic)
    peer.listen(DiagnosticArray, "/diagnostics")
    peer.listen(Odometry, f"/{r}/odom")
    inc = peer.create_publisher(Float64MultiArray, f"/{r}/{args.arm}/joint_increments", DEFAULT)
    jset = peer.create_publisher(JointState, f"/{r}/{args.arm}/joint_set", DEFAULT)
    wheel = peer.create_publisher(Float64, f"/{r}/{args.wheel}/wheel_velocity", DEFAULT) if args.wheel else None
    if not peer.spin_until(lambda: js_topic in peer.latest and inc.get_subscription_count() > 0 and jset.get_subscription_count() > 0, args.timeout):
        return {"error": "bridge not found"}
    peer.spin_until(lambda: False, 0.5)
    home = list(peer.latest[js_topic].position)
    out = {"home": home, "alive_after": {}}

    def alive(label):
        js = peer.wait_for_new(js_topic, 3.0)
        out["alive_after"][label] = None if js is None else list(js.position)

    kind = args.kind
    if kind == "nan":
        m = Float64MultiArray(); m.data = [float("nan")] + [0.0] * 6; inc.publish(m)
        m = Float64MultiArray(); m.data = [float("inf")] * 7; inc.publish(m)
        if wheel:
            wheel.publish(Float64(data=float("nan")))
        peer.spin_until(lambda: False, 0.5); alive("nan")
    elif kind == "wrong_length":
        m = Float64MultiArray(); m.data = [0.3] * 6; inc.publish(m)
        m = Float64MultiArray(); m.data = [0.3] * 9; inc.publish(m)
        j = JointState(); j.name = ["joint1", "joint2"]; j.position = [0.3]; jset.publish(j)
        peer.spin_until(lambda: False, 0.5); alive("wrong_length")
    elif kind == "too_large":
        # More than a joint moves in one control step (1.5 rad/s / 30 Hz = 0.05 rad).
        m = Float64MultiArray(); m.data = [1e308] * 7; inc.publish(m)
        m = Float64MultiArray(); m.data = [0.3] + [0.0] * 6; inc.publish(m)
        peer.spin_until(lambda: False, 0.5); alive("too_large")
    elif kind == "unknown_joint":
        j = JointState(); j.name = ["joint1", "elbow_of_doom"]; j.position = [0.3, 0.3]; jset.publish(j)
        peer.spin_until(lambda: False, 0.5); alive("unknown_joint")
    elif kind == "beyond_limits":
        j = JointState(); j.name = ["joint1"]; j.position = [10.0]; jset.publish(j)
        # Keep it commanded while it travels (2.8 rad at 1.5 rad/s).
        for _ in range(25):
            jset.publish(j); peer.spin_until(lambda: False, 0.1)
        alive("beyond_limits")
    elif kind == "stale":
        x0 = peer.latest[f"/{r}/odom"].pose.pose.position
        for _ in range(15):
            wheel.publish(Float64(data=3.0)); peer.spin_until(lambda: False, 0.1)
        moving = peer.latest[f"/{r}/odom"].twist.twist.linear
        out["speed_while_commanded"] = math.hypot(moving.x, moving.y)
        # Stop sending: after 0.5 s the wheels brake.
        peer.spin_until(lambda: False, 2.0)
        still = peer.latest[f"/{r}/odom"].twist.twist.linear
        out["speed_after_silence"] = math.hypot(still.x, still.y)
        x1 = peer.latest[f"/{r}/odom"].pose.pose.position
        out["moved_m"] = math.dist([x0.x, x0.y], [x1.x, x1.y])
        alive("stale")
    out["diagnostics"] = diag_values(peer)
    return out


def call(peer, srv_type, name, request, timeout):
    client = peer.create_client(srv_type, name)
    try:
        if not client.wait_for_service(timeout_sec=timeout):
            raise RuntimeError(f"no service {name} within {timeout} s")
        future = client.call_async(request)
        deadline = time.monotonic() + timeout
        while not future.done() and time.monotonic() < deadline:
            rclpy.spin_once(peer, timeout_sec=0.05)
        if not future.done():
            raise RuntimeError(f"{name}: no response within {timeout} s")
        return future.result()
    finally:
        peer.destroy_client(client)


def cmd_params(args, peer):
    """What `ros2 param list`, `ros2 param get`, `ros2 param describe` and `ros2 param set` do,
    against the node `--kind` (its fully qualified name): each through the node's
    rcl_interfaces services."""
    from rcl_interfaces.msg import Parameter, ParameterValue
    from rcl_interfaces.srv import (DescribeParameters, GetParameters, ListParameters,
                                    SetParameters)
    from rclpy.parameter import parameter_value_to_python
    node = args.kind
    names = list(call(peer, ListParameters, f"{node}/list_parameters", ListParameters.Request(),
                      args.timeout).result.names)
    values = call(peer, GetParameters, f"{node}/get_parameters",
                  GetParameters.Request(names=names), args.timeout).values
    described = call(peer, DescribeParameters, f"{node}/describe_parameters",
                     DescribeParameters.Request(names=names), args.timeout).descriptors
    set_request = SetParameters.Request(parameters=[Parameter(
        name=names[0], value=ParameterValue(type=4, string_value="changed"))])
    refused = call(peer, SetParameters, f"{node}/set_parameters", set_request, args.timeout).results
    return {
        "values": {n: parameter_value_to_python(v) for n, v in zip(names, values)},
        "read_only": [d.read_only for d in described],
        "set": [{"successful": r.successful, "reason": r.reason} for r in refused],
    }


def cmd_reset(args, peer):
    """Calls the sim bridge's reset (/<robot>/reset, std_srvs/srv/Trigger) as
    `ros2 service call /<robot>/reset std_srvs/srv/Trigger` does, and reports the answer, the
    odometry just before it, and the odometry --drive-seconds of sim time after it."""
    from std_srvs.srv import Trigger
    r = args.robot
    odom = f"/{r}/odom"
    peer.listen(Odometry, odom)
    if peer.wait_for_new(odom, args.timeout) is None:
        return {"error": "no odometry"}
    def pose(m):
        p = m.pose.pose.position
        return {"t": stamp(m), "xyz": [p.x, p.y, p.z]}
    before = pose(peer.latest[odom])
    answer = call(peer, Trigger, f"/{r}/reset", Trigger.Request(), args.timeout)
    first = peer.wait_for_new(odom, args.timeout, lambda m: stamp(m) < before["t"])
    if first is None:
        return {"error": "sim time did not go back", "success": answer.success, "message": answer.message}
    after = pose(first)
    later = peer.wait_for_new(odom, args.timeout + args.drive_seconds,
                              lambda m: stamp(m) >= after["t"] + args.drive_seconds)
    return {"success": answer.success, "message": answer.message, "before": before, "after": after,
            "later": pose(later) if later else None}


def cmd_graph(args, peer):
    """What `ros2 topic info -v` shows of the topic --kind: each publisher's and subscriber's
    node, once discovery has settled (--linger seconds)."""
    peer.spin_until(lambda: False, args.linger)
    def endpoints(infos):
        return [f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos]
    return {"publishers": endpoints(peer.get_publishers_info_by_topic(args.kind)),
            "subscribers": endpoints(peer.get_subscriptions_info_by_topic(args.kind))}


def cmd_once(args, peer):
    """What `ros2 topic pub --once` does, --count times: each time a node of its own in a
    context of its own (a new DDS participant, as a new process has), a publisher with the
    command's QoS (reliable, volatile, keep last 1), a wait for one matched subscription, one
    sample, 0.1 s alive (--within S: S), gone. Sends --goal to /<robot>/goal_pose and reports how many the
    whole-body node counted (`targets_accepted` on /diagnostics) before and after."""
    r = args.robot
    name = f"kumi whole-body node: {r}"
    statuses = latest_diagnostics(peer)
    if not peer.spin_until(lambda: name in statuses, args.timeout):
        return {"error": "no diagnostics from the whole-body node"}
    before = int(statuses[name]["targets_accepted"])
    x, y, z, yaw = [float(v) for v in args.goal.split(",")]
    msg = goal_msg([x, y, z, math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)], f"{r}/odom")
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    unmatched = 0
    for k in range(args.count):
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node(f"kumi_once_{k}", context=context)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        publisher = node.create_publisher(PoseStamped, f"/{r}/goal_pose", qos)
        deadline = time.monotonic() + args.timeout
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        if publisher.get_subscription_count() == 0:
            unmatched += 1
        publisher.publish(msg)
        end = time.monotonic() + (args.within or 0.1)
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.02)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    statuses.clear()
    peer.spin_until(lambda: False, 3.0)
    peer.spin_until(lambda: name in statuses, args.timeout)
    after = int(statuses.get(name, {}).get("targets_accepted", before))
    return {"sent": args.count, "unmatched": unmatched, "arrived": after - before}


def cmd_latency(args, peer):
    """Median and p99 time from publishing increments to the first joint state that moves."""
    io = arm_io(args, peer)
    if io is None:
        return {"error": "bridge not found"}
    js_topic, inc = io
    samples = []
    for i in range(args.samples):
        sign = 1.0 if i % 2 == 0 else -1.0
        peer.spin_until(lambda: False, 0.3)
        m = Float64MultiArray(); m.data = [sign * 0.05] + [0.0] * 6
        t = time.monotonic(); inc.publish(m)
        js = peer.wait_for_new(js_topic, 2.0, lambda js: sign * js.velocity[0] > 0.05)
        if js is not None:
            samples.append(time.monotonic() - t)
    samples.sort()
    pick = lambda q: samples[min(len(samples) - 1, int(q * len(samples)))] if samples else None
    return {"samples": len(samples), "median_ms": pick(0.5) * 1e3 if samples else None, "p99_ms": pick(0.99) * 1e3 if samples else None}


def main():
    p = argparse.ArgumentParser()
    p.add_argument("command")
    p.add_argument("--robot", default="")
    p.add_argument("--arms", default="")
    p.add_argument("--wheels", default="")
    p.add_argument("--arm", default="")
    p.add_argument("--wheel", default="")
    p.add_argument("--joint", type=int, default=0)
    p.add_argument("--increment", type=float, default=0.2)
    p.add_argument("--count", type=int, default=1)
    p.add_argument("--disturb", action="store_true")
    p.add_argument("--wheel-velocity", type=float, default=2.0)
    p.add_argument("--drive-seconds", type=float, default=3.0)
    p.add_argument("--samples", default="")
    p.add_argument("--steps", type=int, default=60)
    p.add_argument("--seed", type=float, default=0.0)
    p.add_argument("--kind", default="")
    p.add_argument("--timeout", type=float, default=15.0)
    p.add_argument("--linger", type=float, default=2.0)
    p.add_argument("--goal", default="")
    p.add_argument("--frame", default="")
    p.add_argument("--within", type=float, default=0.0)
    p.add_argument("--wall", action="store_true")
    p.add_argument("--record", action="store_true", help="reach: report the arm node's increments after the goal")
    p.add_argument("--expect", default="", help="target: comma-separated /diagnostics status names to wait for after the drive")
    args = p.parse_args()
    if args.command == "latency":
        args.samples = int(args.samples or 50)
    note(f"{args.command}: rclpy imported")
    rclpy.init()
    peer = Peer()
    note("node up")
    try:
        out = {
            "observe": cmd_observe, "drive": cmd_drive, "late": cmd_late, "roundtrip": cmd_roundtrip,
            "lockstep": cmd_lockstep, "badinput": cmd_badinput, "latency": cmd_latency,
            "reach": cmd_reach, "armnode": cmd_armnode, "watch": cmd_watch,
            "malformed": cmd_malformed, "zerobyte": cmd_zerobyte, "rosout": cmd_rosout,
            "flood": cmd_flood, "target": cmd_target, "fakelimb": cmd_fakelimb,
            "diagnostics": cmd_diagnostics, "fakeodom": cmd_fakeodom, "params": cmd_params,
            "reset": cmd_reset, "graph": cmd_graph, "once": cmd_once,
        }[args.command](args, peer)
        note(f"{args.command} done")
    except BaseException:
        leave(peer, status=1)
        raise
    # The result is out before rclpy shuts down, so that a shutdown that hangs cannot hold it
    # back: the tests keep a result announced by RESULT_OUT whatever the teardown does after it.
    print(json.dumps(out))
    sys.stdout.flush()
    note(RESULT_OUT)
    leave(peer, status=0)


# Said on stderr once the result is printed and flushed (tests/src/lib.rs reads it).
RESULT_OUT = "result out"


def leave(peer, status, within_s=10.0):
    """Destroys the node and shuts rclpy down; if that hangs past `within_s`, says so and exits
    with `status` (the command's own: 0 after a result, 1 after an exception).

    The timer needs the GIL, which a teardown stuck in rclpy's C code can hold: on CI a fake limb
    said nothing after "done" for a minute. faulthandler's watchdog is a C thread that needs no
    GIL: 5 s later it prints every thread's stack to stderr and exits with status 1."""
    watchdog = threading.Timer(within_s, lambda: (note(f"rclpy shutdown hung {within_s} s; leaving"), os._exit(status)))
    watchdog.daemon = True
    watchdog.start()
    faulthandler.dump_traceback_later(within_s + 5.0, exit=True)
    peer.destroy_node()
    note("node destroyed")
    rclpy.try_shutdown()
    note("rclpy shut down")
    faulthandler.cancel_dump_traceback_later()
    watchdog.cancel()


if __name__ == "__main__":
    main()
