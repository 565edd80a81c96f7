#!/usr/bin/env python3
"""Golden byte vectors of ribreg's serial protocol (core/src/wire.rs), written by an
implementation that shares no code with the Rust side (serde, postcard, cobs).

Run from the repository root (Python 3.11, standard library only, no postcard package):

    python3 tests/golden/gen_wire.py

Writes tests/fixtures/golden/wire.json (checked-in file: Python 3.11.7; the version is
also recorded in the file under "generator").  Running it twice gives identical files.

Everything is written here from the specifications:

* postcard (https://postcard.jamesmunns.com/wire-format): u8 raw; u16/u32/u64 varint
  (7 bits a byte, least significant group first, high bit = more); i32 zigzag then
  varint; f32 4 bytes little-endian IEEE 754; enum discriminant varint(u32) then the
  variant's payload (nothing / the newtype's value / the struct's fields); sequences
  varint(length) then the elements; arrays, tuples and structs element by element,
  no length, no field names.
* CRC-32/ISO-HDLC (zlib.crc32): reflected poly 0xEDB88320, init/xorout 0xFFFFFFFF (check
  value 0xCBF43926 for b"123456789"), appended little-endian.
* COBS (Cheshire & Baker 1999): blocks of code byte n (1..=255) then n-1 non-zero
  bytes; n < 255 stands for a zero after the block, except at the end of the
  payload; a run of 254 non-zero bytes gives code 0xFF with no zero implied.
  Nothing is emitted after a 0xFF block that ends the payload.
* frame = COBS(postcard(Envelope{seq: u16, msg}) + CRC) + 0x00.

The message types are re-declared below as schemas (field order and variant order
as in core/src/wire.rs).  A message value is written in serde's externally tagged
JSON form (unit variant "Name", newtype variant {"Name": value}, struct variant
{"Name": {fields}}), which is what the Rust test deserialises it from with
serde_json.  Every f32 is stored as the exact value of the f32 (Python float repr),
so JSON -> f64 -> f32 is exact.

Self-checks (the script aborts if any fails): varint/zigzag examples of the postcard
spec, the CRC check value, COBS round trips and edge cases against a separate
decoder, every schema variant covered by at least one case, every case decodes back,
and the maximum sizes derived from the schemas are reached by actual messages.
"""

import json
import math
import os
import platform
import random
import struct
import sys
import zlib

SCRIPT = "tests/golden/gen_wire.py"
OUT = os.path.join("tests", "fixtures", "golden", "wire.json")

MAGIC = int.from_bytes(b"RBRG", "little")  # 0x47524252
VERSION = 5

# ---------------------------------------------------------------- primitives


def varint(v):
    assert isinstance(v, int) and v >= 0
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def zigzag32(v):
    assert -(2**31) <= v < 2**31
    return ((v << 1) ^ (v >> 31)) & 0xFFFFFFFF


def f32(x):
    """The f32 nearest to x, as a Python float (exact)."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def crc32(data):
    """CRC-32/ISO-HDLC from the standard library's zlib (an implementation independent of
    the core's bitwise one)."""
    return zlib.crc32(bytes(data)) & 0xFFFFFFFF


def cobs_encode(data):
    out = bytearray()
    block = bytearray()
    for i, b in enumerate(data):
        if b == 0:
            out.append(len(block) + 1)
            out += block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out.append(0xFF)
                out += block
                block = bytearray()
                if i == len(data) - 1:
                    return bytes(out)  # nothing after a 0xFF block that ends the payload
    out.append(len(block) + 1)
    out += block
    return bytes(out)


def cobs_decode(enc):
    """Strict decoder (a second implementation, for the self-checks)."""
    out = bytearray()
    i = 0
    assert 0 not in enc
    while i < len(enc):
        code = enc[i]
        if i + code > len(enc):
            raise ValueError("COBS block runs past the end")
        out += enc[i + 1:i + code]
        i += code
        if code != 0xFF and i < len(enc):
            out.append(0)
    return bytes(out)


# ---------------------------------------------------------------- schemas

U8, U16, U32, U64, I32, F32, BOOL = "u8", "u16", "u32", "u64", "i32", "f32", "bool"
BITS = {U16: 16, U32: 32, U64: 64}


def Array(t, n):
    return ("array", t, n)


def Seq(t, cap):
    return ("seq", t, cap)


def Struct(*fields):
    return ("struct", fields)


def Enum(name, *variants):
    """variants: (name, None | schema); None = unit variant."""
    return ("enum", name, variants)


P3 = Array(F32, 3)
RIGID_W = Array(F32, 12)
PROBE_W = Struct(("width_px", U16), ("height_px", U16), ("footprint_mm", F32), ("depth_mm", F32))
CONFIGURE = Struct(("probe", PROBE_W), ("tcp_t_us", RIGID_W), ("ee_t_tcp", RIGID_W), ("lag_us", I32),
                   ("voxel_mm", F32), ("max_speed_mm_s", F32), ("max_accel_mm_s2", F32),
                   ("standoff_mm", F32), ("target_up", P3), ("partial", BOOL))
NODE = Struct(("p", P3), ("label", U8))
TEMPLATE_SHAPE = Struct(("origin", P3), ("axes", Array(F32, 9)), ("spread", P3),
                        ("skeleton", Array(P3, 30)), ("midline_fraction", Array(F32, 4)))
POSE_W = Struct(("t_us", U64), ("position", P3), ("quat", Array(F32, 4)))
FRAME_W = Struct(("t_us", U64), ("frame", U32), ("pixels", Seq(Array(U16, 2), 96)))
COMMAND = Enum("Command", ("StartSweep", None), ("EndSweep", None), ("Register", None),
               ("Execute", None), ("Abort", None), ("Status", None), ("Result", None),
               ("Cost", None))
TO_CONTROLLER = Enum(
    "ToController",
    ("Hello", Struct(("magic", U32), ("version", U16))),
    ("Configure", CONFIGURE),
    ("TemplateNodes", Struct(("offset", U16), ("total", U16), ("nodes", Seq(NODE, 32)))),
    ("TemplateShape", TEMPLATE_SHAPE),
    ("Waypoints", Struct(("offset", U8), ("total", U8), ("points", Seq(P3, 8)))),
    ("Pose", POSE_W),
    ("Frame", FRAME_W),
    ("Command", COMMAND),
)
STATE = Enum("State", ("Idle", None), ("TemplateLoaded", None), ("Sweeping", None),
             ("Registering", None), ("Ready", None), ("Executing", None), ("Done", None))
NACK_CODE = Enum("NackCode", ("Corrupt", None), ("OutOfOrder", None), ("TooLong", None),
                 ("Version", None), ("BadState", None), ("Invalid", U8))
FAULT = Enum("Fault", ("PoseTimeout", None), ("Registration", U8))
STATUS_W = Struct(("state", STATE), ("expected_seq", U16), ("poses", U32), ("frames_placed", U32),
                  ("frames_refused", U32), ("points", U16), ("progress", U8), ("waypoint", U8))
WAYPOINT_W = Struct(("index", U8), ("total", U8), ("position", P3), ("quality_mm", F32),
                    ("supported", BOOL))
SETPOINT_W = Struct(("t_us", U64), ("position", P3), ("quat", Array(F32, 4)), ("waypoint", U8))
COST_W = Struct(("registration_instructions", U64), ("registration_calls", U32),
                ("worst_call_instructions", U32), ("worst_step_instructions", U32),
                ("worst_receive_instructions", U32), ("peak_stack_bytes", U32),
                ("serial_overruns", U32), ("serial_framing_errors", U32),
                ("serial_dropped_bytes", U32))
REGISTRATION_W = Struct(("hypotheses", U8), ("residual_mm", F32), ("runner_up_mm", F32),
                        ("support_mm", F32), ("min_side_span_percent", U8),
                        ("min_edge_clearance_mm", F32), ("waypoints", U8))
FROM_CONTROLLER = Enum(
    "FromController",
    ("HelloAck", Struct(("magic", U32), ("version", U16), ("max_frame", U16))),
    ("Ack", Struct(("seq", U16))),
    ("Nack", Struct(("seq", U16), ("code", NACK_CODE))),
    ("Status", STATUS_W),
    ("Waypoint", WAYPOINT_W),
    ("Setpoint", SETPOINT_W),
    ("Fault", FAULT),
    ("Cost", COST_W),
    ("Registration", REGISTRATION_W),
)
DIRECTIONS = {"to_controller": TO_CONTROLLER, "from_controller": FROM_CONTROLLER}


def envelope(msg_schema):
    return Struct(("seq", U16), ("msg", msg_schema))


def is_int(v):
    return isinstance(v, int) and not isinstance(v, bool)


def enc(t, v, seen=None):
    """postcard bytes of value v (externally tagged JSON form) of schema t.
    `seen` collects (enum name, variant name) pairs."""
    if t == U8:
        assert is_int(v) and 0 <= v <= 0xFF, v
        return bytes([v])
    if t == BOOL:
        assert isinstance(v, bool), v
        return bytes([int(v)])
    if t in BITS:
        assert is_int(v) and 0 <= v < 2 ** BITS[t], (t, v)
        return varint(v)
    if t == I32:
        assert is_int(v), v
        return varint(zigzag32(v))
    if t == F32:
        assert isinstance(v, float) and f32(v) == v and math.isfinite(v), v
        return struct.pack("<f", v)
    kind = t[0]
    if kind == "array":
        assert isinstance(v, list) and len(v) == t[2], (t, v)
        return b"".join(enc(t[1], x, seen) for x in v)
    if kind == "seq":
        assert isinstance(v, list) and len(v) <= t[2], (t, len(v))
        return varint(len(v)) + b"".join(enc(t[1], x, seen) for x in v)
    if kind == "struct":
        names = [n for n, _ in t[1]]
        assert isinstance(v, dict) and sorted(v) == sorted(names), (names, v)
        return b"".join(enc(ft, v[n], seen) for n, ft in t[1])
    if kind == "enum":
        _, ename, variants = t
        if isinstance(v, str):
            name, payload = v, None
        else:
            assert isinstance(v, dict) and len(v) == 1, v
            (name, payload), = v.items()
        index = [n for n, _ in variants].index(name)
        pt = variants[index][1]
        assert (pt is None) == isinstance(v, str), (ename, name)
        if seen is not None:
            seen.add((ename, name))
        return varint(index) + (b"" if pt is None else enc(pt, payload, seen))
    raise AssertionError(t)


def dec(t, b, i):
    """Inverse of enc: (value, next index).  A separate parser, for the self-check."""
    def take_varint(i, bits):
        v, shift = 0, 0
        while True:
            byte = b[i]
            i += 1
            v |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                assert v < 2**bits
                return v, i
    if t == U8:
        return b[i], i + 1
    if t == BOOL:
        assert b[i] in (0, 1), b[i]
        return b[i] == 1, i + 1
    if t in BITS:
        return take_varint(i, BITS[t])
    if t == I32:
        z, i = take_varint(i, 32)
        return (z >> 1) ^ -(z & 1), i
    if t == F32:
        return struct.unpack_from("<f", b, i)[0], i + 4
    kind = t[0]
    if kind == "array":
        out = []
        for _ in range(t[2]):
            x, i = dec(t[1], b, i)
            out.append(x)
        return out, i
    if kind == "seq":
        n, i = take_varint(i, 64)
        assert n <= t[2]
        out = []
        for _ in range(n):
            x, i = dec(t[1], b, i)
            out.append(x)
        return out, i
    if kind == "struct":
        out = {}
        for n, ft in t[1]:
            out[n], i = dec(ft, b, i)
        return out, i
    if kind == "enum":
        index, i = take_varint(i, 32)
        name, pt = t[2][index]
        if pt is None:
            return name, i
        x, i = dec(pt, b, i)
        return {name: x}, i
    raise AssertionError(t)


def max_size(t):
    """Worst-case postcard size of schema t."""
    if t in (U8, BOOL):
        return 1
    if t in BITS:
        return len(varint(2 ** BITS[t] - 1))
    if t == I32:
        return len(varint(zigzag32(-(2**31))))
    if t == F32:
        return 4
    kind = t[0]
    if kind == "array":
        return t[2] * max_size(t[1])
    if kind == "seq":
        return len(varint(t[2])) + t[2] * max_size(t[1])
    if kind == "struct":
        return sum(max_size(ft) for _, ft in t[1])
    if kind == "enum":
        return max(len(varint(i)) + (0 if pt is None else max_size(pt))
                   for i, (_, pt) in enumerate(t[2]))
    raise AssertionError(t)


def max_cobs(n):
    """Longest COBS encoding of n >= 1 bytes.  Each zero becomes a code byte, so the
    overhead is the number of 0xFF blocks (at most floor(n/254)) plus one for the final
    block, which is absent only when the payload ends with a 0xFF block; so at most
    ceil(n/254) (self-checked on random payloads and reached by all-non-zero ones)."""
    return n + -(-n // 254)


def frame_of(direction, seq, msg, seen=None):
    post = enc(envelope(DIRECTIONS[direction]), {"seq": seq, "msg": msg}, seen)
    crc = crc32(post)
    body = post + crc.to_bytes(4, "little")
    return post, crc, cobs_encode(body) + b"\x00"


# ---------------------------------------------------------------- self-checks


def self_checks():
    # postcard spec examples (varint and zigzag)
    for v, h in ((0, "00"), (127, "7f"), (128, "8001"), (16383, "ff7f"), (16384, "808001"),
                 (65535, "ffff03"), (2**32 - 1, "ffffffff0f"), (2**64 - 1, "ffffffffffffffffff01")):
        assert varint(v).hex() == h, (v, varint(v).hex())
    for v, z in ((0, 0), (-1, 1), (1, 2), (-2, 3), (2**31 - 1, 2**32 - 2), (-(2**31), 2**32 - 1)):
        assert zigzag32(v) == z, v
    assert struct.pack("<f", -0.0).hex() == "00000080"
    assert struct.pack("<f", 1.0).hex() == "0000803f"
    assert crc32(b"123456789") == 0xCBF43926
    assert MAGIC == 0x47524252
    # COBS: examples from Cheshire & Baker / Wikipedia, then random round trips.
    for raw, h in ((b"\x00", "0101"), (b"\x00\x00", "010101"), (b"\x11\x22\x00\x33", "0311220233"),
                   (b"\x11\x22\x33\x44", "0511223344"), (b"\x11\x00\x00\x00", "0211010101"),
                   (bytes(range(1, 255)), "ff" + bytes(range(1, 255)).hex()),
                   (bytes(range(0, 255)), "01ff" + bytes(range(1, 255)).hex()),
                   (bytes(range(1, 256)), "ff" + bytes(range(1, 255)).hex() + "02ff"),
                   (bytes(range(1, 255)) + b"\x00", "ff" + bytes(range(1, 255)).hex() + "0101")):
        assert cobs_encode(raw).hex() == h, (raw.hex(), cobs_encode(raw).hex())
    g = random.Random(7)
    for n in list(range(1, 600)) + [253, 254, 255, 507, 508, 509]:
        for zeros in (0.0, 0.01, 0.3):
            raw = bytes(0 if g.random() < zeros else g.randrange(1, 256) for _ in range(n))
            e = cobs_encode(raw)
            assert 0 not in e and cobs_decode(e) == raw and len(e) <= max_cobs(n), (n, zeros)
    # The worst case of max_cobs is reached.
    for n in (1, 253, 254, 255, 508, 598):
        assert len(cobs_encode(bytes([1]) * n)) == max_cobs(n)


# ---------------------------------------------------------------- cases

G = random.Random(20240611)


def r32(lo, hi, decimals=3):
    return f32(round(G.uniform(lo, hi), decimals))


def p3(lo=-300.0, hi=300.0):
    return [r32(lo, hi) for _ in range(3)]


def rot_z(deg):
    c, s = f32(math.cos(math.radians(deg))), f32(math.sin(math.radians(deg)))
    return [c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0]


U64_MAX, U32_MAX, U16_MAX = 2**64 - 1, 2**32 - 1, 2**16 - 1
F32_MAX = f32(3.4028234663852886e38)
F32_MIN_POSITIVE = f32(1.1754943508222875e-38)
F32_MIN_SUBNORMAL = f32(1.401298464324817e-45)
ONE_E_MINUS_7 = f32(1e-7)


def cases():
    out = []

    def add(name, description, direction, seq, msg):
        out.append({"name": name, "description": description, "direction": direction,
                    "seq": seq, "message": msg})

    to, fr = "to_controller", "from_controller"

    add("hello", "handshake, sequence 0", to, 0, {"Hello": {"magic": MAGIC, "version": VERSION}})
    add("hello_bad_version", "handshake with a foreign magic and version u16::MAX", to, 0,
        {"Hello": {"magic": 0xDEADBEEF, "version": U16_MAX}})
    tcp = rot_z(90.0)
    tcp[1] = -1.0
    tcp[4] = -0.0  # cos 90° written as -0.0: the sign bit must survive
    add("configure", "calibration, negative lag (-268 ms), -0.0 and 1e-7 among the floats", to, 1,
        {"Configure": {"probe": {"width_px": 384, "height_px": 480, "footprint_mm": f32(38.4),
                                 "depth_mm": f32(60.0)},
                       "tcp_t_us": tcp[:9] + [f32(12.5), f32(-3.25), f32(145.0)],
                       "ee_t_tcp": rot_z(30.0) + [ONE_E_MINUS_7, -0.0, f32(210.75)],
                       "lag_us": -268000, "voxel_mm": f32(2.0), "max_speed_mm_s": f32(20.0),
                       "max_accel_mm_s2": f32(100.0), "standoff_mm": f32(5.0),
                       "target_up": [f32(0.0), f32(0.25), f32(-1.0)], "partial": False}})
    add("configure_extremes", "lag i32::MIN, f32::MAX, smallest normal and subnormal f32", to, 2,
        {"Configure": {"probe": {"width_px": U16_MAX, "height_px": 0, "footprint_mm": F32_MAX,
                                 "depth_mm": F32_MIN_SUBNORMAL},
                       "tcp_t_us": [F32_MIN_POSITIVE, -F32_MIN_POSITIVE, -F32_MAX] + [0.0] * 9,
                       "ee_t_tcp": [-0.0] * 12,
                       "lag_us": -(2**31), "voxel_mm": ONE_E_MINUS_7, "max_speed_mm_s": -ONE_E_MINUS_7,
                       "max_accel_mm_s2": -F32_MIN_SUBNORMAL, "standoff_mm": f32(1e30),
                       "target_up": [F32_MAX, -0.0, F32_MIN_SUBNORMAL], "partial": True}})
    add("configure_lag_max", "lag i32::MAX", to, 3,
        {"Configure": {"probe": {"width_px": 640, "height_px": 512, "footprint_mm": f32(50.0),
                                 "depth_mm": f32(80.0)},
                       "tcp_t_us": rot_z(-45.0) + p3(), "ee_t_tcp": rot_z(180.0) + p3(),
                       "lag_us": 2**31 - 1, "voxel_mm": f32(1.5), "max_speed_mm_s": f32(35.5),
                       "max_accel_mm_s2": f32(250.0), "standoff_mm": f32(0.0),
                       "target_up": [0.0, 0.0, 0.0], "partial": False}})
    g = random.Random(11)
    nodes = [{"p": p3(-150.0, 150.0), "label": g.randrange(0, 6)} for _ in range(32)]
    nodes[0]["label"], nodes[1]["label"] = 0, 5
    add("template_nodes_full", "a full 32-node chunk (offset 160 of 400)", to, 0x7F,
        {"TemplateNodes": {"offset": 160, "total": 400, "nodes": nodes}})
    add("template_nodes_last", "the last chunk of 400 nodes: 16 nodes at offset 384", to, 0x80,
        {"TemplateNodes": {"offset": 384, "total": 400,
                           "nodes": [{"p": p3(-150.0, 150.0), "label": i % 6} for i in range(16)]}})
    add("template_nodes_empty", "an empty chunk", to, 0x3FFF,
        {"TemplateNodes": {"offset": 0, "total": 0, "nodes": []}})
    add("template_shape", "frame, axes, spread, 30 skeleton points, midline fractions", to, 0x4000,
        {"TemplateShape": {"origin": p3(), "axes": rot_z(12.0), "spread": p3(0.0, 120.0),
                           "skeleton": [p3(-150.0, 150.0) for _ in range(30)],
                           "midline_fraction": [f32(0.5), f32(0.4375), f32(0.5), f32(0.625)]}})
    add("waypoints_full", "a full chunk of 8 waypoints", to, 42,
        {"Waypoints": {"offset": 0, "total": 10, "points": [p3() for _ in range(8)]}})
    add("waypoints_last", "the last 2 of 10 waypoints", to, 43,
        {"Waypoints": {"offset": 8, "total": 10, "points": [p3(), p3()]}})
    add("waypoints_u8_max", "u8::MAX offset and total, no points", to, 44,
        {"Waypoints": {"offset": 255, "total": 255, "points": []}})
    q = [f32(0.7071068), f32(-0.7071068), ONE_E_MINUS_7, -0.0]
    add("pose_time_max", "tracker time u64::MAX", to, 0xFFFF,
        {"Pose": {"t_us": U64_MAX, "position": [f32(412.125), f32(-87.5), f32(230.0)], "quat": q}})
    add("pose", "an ordinary pose", to, 1234,
        {"Pose": {"t_us": 1_718_000_123_456, "position": p3(), "quat": [f32(1.0), 0.0, 0.0, 0.0]}})
    add("frame_96", "a 96-pixel frame (a 384-pixel image, every 4th column)", to, 5000,
        {"Frame": {"t_us": 1_718_000_123_789, "frame": 577,
                   "pixels": [[(4 * i) * 16 + 8, 16 * (200 + (i * 7) % 90) + (i % 16)] for i in range(96)]}})
    add("frame_max", "the largest message: 96 pixels at u16::MAX, t_us u64::MAX, frame u32::MAX, "
        "seq u16::MAX (the 602-byte frame)", to, 0xFFFF,
        {"Frame": {"t_us": U64_MAX, "frame": U32_MAX, "pixels": [[U16_MAX, U16_MAX]] * 96}})
    add("frame_empty", "a frame with no bone pixels, time 0", to, 7,
        {"Frame": {"t_us": 0, "frame": 0, "pixels": []}})
    for i, (c, _) in enumerate(COMMAND[2]):
        add("command_" + snake(c), f"Command::{c}", to, [1, 0x7F, 0x80, 300, 0x3FFF, 0x4000, 0xFFFF, 2][i],
            {"Command": c})

    add("hello_ack", "handshake answer, sequence 0", fr, 0,
        {"HelloAck": {"magic": MAGIC, "version": VERSION, "max_frame": 602}})
    add("ack", "acknowledges host message 0x80", fr, 1, {"Ack": {"seq": 0x80}})
    add("ack_seq_max", "acknowledges host message u16::MAX", fr, 0xFFFF, {"Ack": {"seq": U16_MAX}})
    for i, (c, pt) in enumerate(NACK_CODE[2]):
        code = {c: 19} if pt is not None else c
        add("nack_" + snake(c), f"Nack with NackCode::{c}" + ("(19)" if pt is not None else ""), fr,
            2 + i, {"Nack": {"seq": [0, 0x7F, 0x80, 0x3FFF, 0x4000, 0xFFFF][i], "code": code}})
    for i, (s, _) in enumerate(STATE[2]):
        add("status_" + snake(s), f"Status in State::{s}", fr, 100 + i,
            {"Status": {"state": s, "expected_seq": [0, 1, 0x7F, 0x80, 1000, 0x4000, 0xFFFF][i],
                        "poses": [0, 1, 2000, 2**21, 2**28, 123456789, U32_MAX][i],
                        "frames_placed": 577 * i, "frames_refused": 3 * i,
                        "points": [0, 0, 512, 2048, 2048, 2048, U16_MAX][i],
                        "progress": [0, 0, 0, 37, 100, 100, 255][i], "waypoint": [0, 0, 0, 0, 0, 4, 10][i]}})
    add("waypoint", "one mapped waypoint with its quality", fr, 200,
        {"Waypoint": {"index": 3, "total": 10, "position": p3(), "quality_mm": f32(0.8125),
                      "supported": True}})
    add("waypoint_quality_tiny", "quality 1e-7 mm, -0.0 in the position", fr, 201,
        {"Waypoint": {"index": 255, "total": 255, "position": [-0.0, 0.0, F32_MIN_SUBNORMAL],
                      "quality_mm": ONE_E_MINUS_7, "supported": False}})
    add("setpoint", "a setpoint", fr, 0x2345,
        {"Setpoint": {"t_us": 987_654_321, "position": p3(), "quat": [f32(0.5), f32(-0.5), f32(0.5), f32(-0.5)],
                      "waypoint": 4}})
    add("setpoint_max", "a setpoint at its largest: t_us u64::MAX", fr, 0xFFFF,
        {"Setpoint": {"t_us": U64_MAX, "position": [F32_MAX, -F32_MAX, -0.0], "quat": [1.0, 0.0, 0.0, 0.0],
                      "waypoint": 255}})
    add("fault_pose_timeout", "Fault::PoseTimeout", fr, 0x7F, {"Fault": "PoseTimeout"})
    add("fault_registration", "Fault::Registration(10): core error RigidFit", fr, 0x80,
        {"Fault": {"Registration": 10}})
    add("cost", "measured costs: u64 and u32 varints of several lengths", fr, 0x4000,
        {"Cost": {"registration_instructions": 123_456_789_012, "registration_calls": 1093,
                  "worst_call_instructions": 141_233, "worst_step_instructions": 0,
                  "worst_receive_instructions": 0xFFFF_FFFF, "peak_stack_bytes": 127,
                  "serial_overruns": 0, "serial_framing_errors": 128,
                  "serial_dropped_bytes": 16_384}})
    add("cost_max", "the largest controller message (version 2): every cost field at its maximum",
        fr, 0xFFFF,
        {"Cost": {"registration_instructions": U64_MAX, "registration_calls": 0xFFFF_FFFF,
                  "worst_call_instructions": 0xFFFF_FFFF, "worst_step_instructions": 0xFFFF_FFFF,
                  "worst_receive_instructions": 0xFFFF_FFFF, "peak_stack_bytes": 0xFFFF_FFFF,
                  "serial_overruns": 0xFFFF_FFFF, "serial_framing_errors": 0xFFFF_FFFF,
                  "serial_dropped_bytes": 0xFFFF_FFFF}})
    add("registration", "the registration's confidence before its waypoints (version 5)", fr, 0x4001,
        {"Registration": {"hypotheses": 2, "residual_mm": f32(3.575), "runner_up_mm": f32(5.8),
                          "support_mm": f32(4.25), "min_side_span_percent": 255,
                          "min_edge_clearance_mm": f32(12.5), "waypoints": 10}})

    # COBS edges (found by search; the script asserts the property each is made for).
    add("cobs_tail_254", "payload ends in a run of exactly 254 non-zero bytes: a final 0xFF "
        "block with nothing after it", to, 0x1234, cobs_tail_254())
    add("cobs_254_then_zero", "a run of 254 non-zero bytes from the start of the payload, then a "
        "zero: 0xFF block, then code 0x01", to, 0x0102, cobs_254_then_zero())
    return out


def snake(name):
    return "".join("_" + c.lower() if c.isupper() and i else c.lower() for i, c in enumerate(name))


def cobs_tail_254():
    """Frame message whose payload (envelope + CRC) ends in exactly 254 non-zero bytes:
    a pixel with v = 0 (one zero byte), then 62 pixels of 2-byte varints (248 bytes), one
    pixel of 1-byte varints (2 bytes), then the CRC (4 bytes, searched to be non-zero)."""
    for t in range(1000, 100000):
        px = [[200 + 16 * i, 300 + 16 * i] for i in range(16)] + [[4000, 0]]
        px += [[1000 + 16 * i, 2000 + 16 * i] for i in range(62)] + [[5, 7]]
        msg = {"Frame": {"t_us": t, "frame": 99, "pixels": px}}
        post, crc, fr = frame_of("to_controller", 0x1234, msg)
        body = post + crc.to_bytes(4, "little")
        if 0 not in body[-254:] and body[-255] == 0:
            enc = fr[:-1]
            assert cobs_decode(enc) == body
            # the last block is a 0xFF block of 254 bytes and ends the frame
            i, last = 0, None
            while i < len(enc):
                last = i
                i += enc[i]
            assert enc[last] == 0xFF and last == len(enc) - 255
            return msg
    raise AssertionError("no cobs_tail_254 message found")


def cobs_254_then_zero():
    """seq 0x0102 (2 bytes), tag (1), t_us of 5 bytes, frame of 3 bytes, length (1): 12
    bytes, then 60 pixels and one u of 2 bytes each (242): 254 non-zero bytes, then v = 0."""
    msg = {"Frame": {"t_us": 2**30 + 12345, "frame": 20000,
                     "pixels": [[130 + i, 5000 + 3 * i] for i in range(60)] + [[777, 0]]
                     + [[150 + 16 * i, 160 + 16 * i] for i in range(19)]}}
    post, crc, fr = frame_of("to_controller", 0x0102, msg)
    assert 0 not in post[:254] and post[254] == 0
    enc = fr[:-1]
    assert enc[0] == 0xFF and enc[255] == 0x01, enc[:260].hex()
    return msg


# ---------------------------------------------------------------- main


def main():
    if not os.path.isdir(os.path.join("tests", "golden")):
        sys.exit("run from the repository root: python3 tests/golden/gen_wire.py")
    self_checks()
    seen = set()
    doc_cases = []
    for c in cases():
        schema = envelope(DIRECTIONS[c["direction"]])
        post, crc, fr = frame_of(c["direction"], c["seq"], c["message"], seen)
        # Independent read-back: COBS decode, CRC, postcard parse.
        assert fr[-1] == 0 and 0 not in fr[:-1]
        body = cobs_decode(fr[:-1])
        assert body[:-4] == post and int.from_bytes(body[-4:], "little") == crc32(post)
        val, end = dec(schema, post, 0)
        assert end == len(post) and val == {"seq": c["seq"], "msg": c["message"]}, c["name"]
        c["postcard"] = post.hex()
        c["crc"] = crc
        c["frame"] = fr.hex()
        c["frame_len"] = len(fr)
        doc_cases.append(c)
    names = [c["name"] for c in doc_cases]
    assert len(set(names)) == len(names)
    # Every variant of every enum is in some case.
    for e in (TO_CONTROLLER, FROM_CONTROLLER, COMMAND, NACK_CODE, FAULT, STATE):
        missing = [v for v, _ in e[2] if (e[1], v) not in seen]
        assert not missing, (e[1], missing)

    max_to = max_size(TO_CONTROLLER)
    max_from = max_size(FROM_CONTROLLER)
    max_frame = max_cobs(max(max_to, max_from) + max_size(U16) + 4) + 1
    by_name = {c["name"]: c for c in doc_cases}
    assert len(bytes.fromhex(by_name["frame_max"]["postcard"])) == max_size(U16) + max_to
    assert by_name["frame_max"]["frame_len"] == max_frame
    assert len(bytes.fromhex(by_name["cost_max"]["postcard"])) == max_size(U16) + max_from

    gen = {"script": SCRIPT, "python": platform.python_version()}
    constants = {"magic": MAGIC, "version": VERSION, "crc_check_123456789": crc32(b"123456789"),
                 "max_to_controller": max_to, "max_from_controller": max_from, "max_frame": max_frame}
    text = ('{"generator":' + json.dumps(gen, separators=(",", ":"))
            + ',\n"constants":' + json.dumps(constants, separators=(",", ":"))
            + ',\n"cases":[\n'
            + ",\n".join(json.dumps(c, separators=(",", ":"), allow_nan=False) for c in doc_cases)
            + "\n]}\n")
    json.loads(text)
    with open(OUT, "w", encoding="utf-8") as f:
        f.write(text)
    print(f"{OUT}: {len(doc_cases)} cases, {os.path.getsize(OUT)} bytes; max message "
          f"{max_to} (to) / {max_from} (from) bytes, max frame {max_frame} bytes")


if __name__ == "__main__":
    main()
