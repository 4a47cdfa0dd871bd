"""Hostile input for the SITL's ports, seeded: malformed MAVLink datagrams and control requests.

What the fuzz test (``tests/test_sitl_fuzz.py``) and the fuzz benchmark (``bench/sitl_fuzz.py``) throw at a running
SITL. One seed gives the same sequence on any machine.

MAVLink datagrams (:class:`MavlinkFuzzer`), in kinds chosen at random:

- ``structured``: every message the SITL handles (commands, setpoints, parameters, modes, timesync, the mission
  protocol, MAVLink FTP, the joystick), addressed to it, with NaN, infinity or float32 extremes in every float field
  and random integers elsewhere;
- ``any_message``: a message of any other type in the dialect with random fields;
- ``mutated``: a valid frame truncated, with a flipped bit, a wrong length byte, a bad CRC or trailing junk;
- ``bad_signature``: a signed frame with a valid CRC and a signature made with another key;
- ``unknown_id``: a well-formed frame of a message id the dialect does not know;
- ``noise``: random bytes, sometimes behind a MAVLink start marker;
- ``mavlink1``: a structured message packed as MAVLink 1.

Input that is well formed *and* meaningful (a valid mode change, any finite value of a real parameter: the SITL
stores it as PX4 does and flies with it clamped) is not fuzz but a command, so the structured kind never builds one:
a float field always holds a value the SITL must refuse (a real parameter gets NaN or infinity), and a mode field a
mode that does not exist. Messages of integers only (MANUAL_CONTROL, MISSION_COUNT, MISSION_CLEAR_ALL, FTP
headers) are random and so sometimes meaningful: they act only where the state allows (sticks in POSCTL, an upload
the fuzzer's own items must complete, which random items do not). Control requests (:class:`ControlFuzzer`)
likewise: broken JSON, NaN and infinity, numbers that overflow, deep nesting, wrong types (``"lost": "false"``),
values out of range, oversized strings, unknown commands and acknowledgements from a stranger; never ``shutdown``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

FLOAT_SPECIALS = (float("nan"), float("inf"), float("-inf"), 3.4e38, -3.4e38, 1e30, -1e30)
NON_FINITE = FLOAT_SPECIALS[:3]
HANDLED = (
    "COMMAND_LONG",
    "COMMAND_INT",
    "SET_POSITION_TARGET_LOCAL_NED",
    "PARAM_REQUEST_LIST",
    "PARAM_REQUEST_READ",
    "PARAM_SET",
    "SET_MODE",
    "TIMESYNC",
    "MISSION_REQUEST_LIST",
    "MISSION_REQUEST_INT",
    "MISSION_REQUEST",
    "MISSION_COUNT",
    "MISSION_ITEM_INT",
    "MISSION_ITEM",
    "MISSION_CLEAR_ALL",
    "MISSION_SET_CURRENT",
    "MISSION_ACK",
    "MANUAL_CONTROL",
    "FILE_TRANSFER_PROTOCOL",
)
HANDLED_COMMANDS = (
    mavlink.MAV_CMD_COMPONENT_ARM_DISARM,
    mavlink.MAV_CMD_NAV_TAKEOFF,
    mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
    mavlink.MAV_CMD_DO_SET_MODE,
    mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
    mavlink.MAV_CMD_REQUEST_MESSAGE,
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    mavlink.MAV_CMD_DO_SET_HOME,
    mavlink.MAV_CMD_DO_CHANGE_SPEED,
    mavlink.MAV_CMD_GET_MESSAGE_INTERVAL,
    mavlink.MAV_CMD_GET_HOME_POSITION,
    mavlink.MAV_CMD_DO_REPOSITION,
    mavlink.MAV_CMD_DO_ORBIT,
    mavlink.MAV_CMD_MISSION_START,
    mavlink.MAV_CMD_DO_SET_MISSION_CURRENT,
    mavlink.MAV_CMD_DO_PAUSE_CONTINUE,
    519,  # REQUEST_PROTOCOL_VERSION
)
PARAM_NAMES = (
    b"COM_OF_LOSS_T",
    b"COM_OBL_RC_ACT",
    b"MPC_XY_VEL_MAX",
    b"MIS_TAKEOFF_ALT",
    b"MAV_SYS_ID",
    b"NAV_RCL_ACT",
)
KINDS = ("structured", "any_message", "mutated", "bad_signature", "unknown_id", "noise", "mavlink1")
KIND_WEIGHTS = (0.40, 0.12, 0.18, 0.08, 0.06, 0.10, 0.06)
INT_RANGES = {
    "uint8_t": (0, 255),
    "int8_t": (-128, 127),
    "uint16_t": (0, 65535),
    "int16_t": (-32768, 32767),
    "uint32_t": (0, 2**32 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint64_t": (0, 2**64 - 1),
    "int64_t": (-(2**63), 2**63 - 1),
}
OTHER_TYPES = tuple(
    cls for cls in mavlink.mavlink_map.values() if cls.msgname not in HANDLED and cls.msgname != "HEARTBEAT"
)


class MavlinkFuzzer:
    """Seeded malformed MAVLink 2 datagrams for a vehicle with ``target_system``."""

    def __init__(self, seed: int, target_system: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.target_system = target_system
        self.counts: dict[str, int] = dict.fromkeys(KINDS, 0)
        self._mav = mavlink.MAVLink(None, srcSystem=200, srcComponent=190)
        self._signer = mavlink.MAVLink(None, srcSystem=201, srcComponent=190)
        self._signer.signing.secret_key = bytes(self.rng.integers(0, 256, 32, dtype=np.uint8))
        self._signer.signing.sign_outgoing = True

    def datagrams(self, count: int) -> Iterator[bytes]:
        """``count`` datagrams."""
        for _ in range(count):
            kind = str(self.rng.choice(KINDS, p=KIND_WEIGHTS))
            self.counts[kind] += 1
            yield getattr(self, f"_{kind}")()

    # -- building blocks -------------------------------------------------------------------------------------------
    def _int(self, ctype: str) -> int:
        low, high = INT_RANGES[ctype]
        if self.rng.random() < 0.3:
            return (low, high, 0)[int(self.rng.integers(3))]
        return int(self.rng.integers(low, high, endpoint=True, dtype=np.uint64 if ctype == "uint64_t" else np.int64))

    def _value(self, ctype: str) -> Any:
        if ctype in ("float", "double"):
            return float(self.rng.choice(FLOAT_SPECIALS))
        if ctype == "char":
            return bytes(self.rng.integers(0, 256, int(self.rng.integers(0, 20)), dtype=np.uint8))
        return self._int(ctype)

    def _fields(self, cls: Any) -> dict[str, Any]:
        fields: dict[str, Any] = {}
        for name, ctype in zip(cls.fieldnames, cls.fieldtypes, strict=True):
            length = cls.array_lengths[cls.ordered_fieldnames.index(name)]
            if length and ctype != "char":
                fields[name] = [self._value(ctype) for _ in range(length)]
            elif ctype == "char" and not length:  # one character
                fields[name] = bytes([int(self.rng.integers(256))])
            else:
                fields[name] = self._value(ctype)
        return fields

    def _pack(self, cls: Any, fields: dict[str, Any], mav: Any = None, mavlink1: bool = False) -> bytes:
        codec = mav or self._mav
        msg = cls(**fields)
        data: bytes = msg.pack(codec, force_mavlink1=mavlink1)
        codec.seq = (codec.seq + 1) % 256
        return data

    def _structured_message(self) -> tuple[Any, dict[str, Any]]:
        name = str(self.rng.choice(HANDLED))
        cls = mavlink.mavlink_map[getattr(mavlink, f"MAVLINK_MSG_ID_{name}")]
        fields = self._fields(cls)
        if "target_system" in fields:
            fields["target_system"] = int(self.rng.choice([self.target_system, 0, self._int("uint8_t")]))
        if "target_component" in fields:
            fields["target_component"] = int(self.rng.choice([1, 0, self._int("uint8_t")]))
        if "command" in fields and self.rng.random() < 0.8:
            fields["command"] = int(self.rng.choice(HANDLED_COMMANDS))
        if name == "SET_MODE":  # a custom mode whose main mode does not exist (0, or 8 and up)
            main = int(self.rng.choice([0, int(self.rng.integers(8, 256))]))
            fields["custom_mode"] = (fields["custom_mode"] & 0xFF00FFFF) | (main << 16)
        if name in ("PARAM_SET", "PARAM_REQUEST_READ") and self.rng.random() < 0.5:
            fields["param_id"] = bytes(self.rng.choice(PARAM_NAMES))
            if name == "PARAM_SET":
                # As PX4, the SITL stores any finite value of a parameter's type, even out of range, and flies with it
                # clamped (COM_OF_LOSS_T -1e30 flies as 0 s: offboard is lost at once). That is a command, not fuzz:
                # a real parameter only ever gets a value it must refuse, not a number at all.
                fields["param_value"] = float(self.rng.choice(NON_FINITE))
                fields["param_type"] = mavlink.MAV_PARAM_TYPE_REAL32
        if name == "COMMAND_INT":  # x, y are int32 (lat/lon); z is the float
            fields["z"] = float(self.rng.choice(FLOAT_SPECIALS))
        return cls, fields

    # -- the kinds ---------------------------------------------------------------------------------------------------
    def _structured(self) -> bytes:
        cls, fields = self._structured_message()
        return self._pack(cls, fields)

    def _mavlink1(self) -> bytes:
        cls, fields = self._structured_message()
        if cls.id > 255:
            return self._pack(cls, fields)
        return self._pack(cls, fields, mavlink1=True)

    def _any_message(self) -> bytes:
        cls = OTHER_TYPES[int(self.rng.integers(len(OTHER_TYPES)))]
        fields = self._fields(cls)
        for key in ("target_system",):
            if key in fields:
                fields[key] = self.target_system
        return self._pack(cls, fields)

    def _valid_frame(self) -> bytearray:
        cls, fields = self._structured_message()
        return bytearray(self._pack(cls, fields))

    def _mutated(self) -> bytes:
        frame = self._valid_frame()
        how = int(self.rng.integers(5))
        if how == 0 and len(frame) > 2:  # truncated
            return bytes(frame[: int(self.rng.integers(1, len(frame)))])
        if how == 1:  # one bit flipped anywhere
            i = int(self.rng.integers(len(frame)))
            frame[i] ^= 1 << int(self.rng.integers(8))
        elif how == 2:  # the length byte lies
            frame[1] = int(self.rng.integers(256))
        elif how == 3:  # bad CRC
            frame[-1] ^= 0xFF
        else:  # junk after the frame
            frame += bytes(self.rng.integers(0, 256, int(self.rng.integers(1, 40)), dtype=np.uint8))
        return bytes(frame)

    def _bad_signature(self) -> bytes:
        cls, fields = self._structured_message()
        return self._pack(cls, fields, mav=self._signer)

    def _unknown_id(self) -> bytes:
        while True:
            msg_id = int(self.rng.integers(0, 1 << 24))
            if msg_id not in mavlink.mavlink_map:
                break
        payload = bytes(self.rng.integers(0, 256, int(self.rng.integers(0, 255)), dtype=np.uint8))
        header = bytes([0xFD, len(payload), 0, 0, 0, 200, 190]) + msg_id.to_bytes(3, "little")
        crc = mavlink.x25crc(header[1:] + payload)
        crc.accumulate(bytes([int(self.rng.integers(256))]))  # no CRC extra is known for it: any byte
        checksum: int = crc.crc
        return header + payload + checksum.to_bytes(2, "little")

    def _noise(self) -> bytes:
        data = bytes(self.rng.integers(0, 256, int(self.rng.integers(1, 300)), dtype=np.uint8))
        return (b"\xfd" + data) if self.rng.random() < 0.5 else data


CONTROL_COMMANDS = (
    "ping",
    "state",
    "pilot_mode",
    "pilot_sticks",
    "rc_loss",
    "wind",
    "lockstep_subscribe",
    "lockstep_ack",
    "camera_fail",
    "link_loss",
    "people",
    "place_person",
)
BAD_VALUES: tuple[Any, ...] = (
    "false",
    "true",
    "NaN",
    None,
    [],
    {},
    [1, 2],
    -1,
    10**30,
    1e308,
    -1e308,
    "x" * 5000,
    [[[[[[[[[[1]]]]]]]]]],
    {"a": {"b": {"c": {"d": {"e": {"f": {"g": {"h": {"i": 1}}}}}}}}},
)


class ControlFuzzer:
    """Seeded hostile control-channel datagrams (never ``shutdown``, never a valid state change)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.counts: dict[str, int] = {}

    def requests(self, count: int) -> Iterator[bytes]:
        """``count`` datagrams."""
        for _ in range(count):
            kind, data = self._one()
            self.counts[kind] = self.counts.get(kind, 0) + 1
            yield data

    def _bad(self) -> Any:
        return BAD_VALUES[int(self.rng.integers(len(BAD_VALUES)))]

    def _one(self) -> tuple[str, bytes]:
        how = int(self.rng.integers(9))
        cmd = str(self.rng.choice(CONTROL_COMMANDS))
        if how == 0:
            return "not_json", bytes(self.rng.integers(0, 256, int(self.rng.integers(1, 200)), dtype=np.uint8))
        if how == 1:
            depth = int(self.rng.integers(10, 3000))
            return "deep", (b'{"cmd":"ping","x":' + b"[" * depth + b"]" * depth + b"}")
        if how == 2:
            constant = str(self.rng.choice(["NaN", "Infinity", "-Infinity", "1e999", "-1e999"]))
            key = str(self.rng.choice(["seq", "north", "lost", "ned_mps", "failed", "id"]))
            return "non_finite", f'{{"cmd":"{cmd}","{key}":{constant}}}'.encode()
        if how == 3:
            return "not_object", json.dumps(self._bad()).encode()
        if how == 4:
            return "unknown_cmd", json.dumps({"cmd": "x" * int(self.rng.integers(1, 200))}).encode()
        if how == 5:  # the right command, every field wrong
            fields = {
                "pilot_mode": {"mode": self._bad()},
                "pilot_sticks": {k: self._bad() for k in ("north", "east", "down")},
                "rc_loss": {"lost": self._bad()},
                "wind": {"ned_mps": [self._bad(), [1e4, 0, 0], [41, 0, 0], ["a", "b", "c"]][int(self.rng.integers(4))]},
                "lockstep_ack": {"seq": self._bad(), "expect": self._bad(), "mavlink_sent": self._bad()},
                "camera_fail": {"failed": self._bad()},
                "link_loss": {"lost": self._bad()},
                "place_person": {"north_m": self._bad()},  # east_m missing: never a valid request
            }.get(cmd, {"extra": self._bad()})
            return "wrong_fields", json.dumps({"cmd": cmd, **fields}).encode()
        if how == 6:  # out of range, right types
            fields = {
                "pilot_sticks": {"north": float(self.rng.uniform(1.01, 1e6)) * float(self.rng.choice([-1, 1]))},
                "wind": {"ned_mps": [float(self.rng.uniform(41, 1e300)), 0.0, 0.0]},
                "lockstep_ack": {"seq": int(self.rng.integers(0, 1000)), "mavlink_sent": 1, "sysid": 300, "compid": 1},
            }
            chosen = str(self.rng.choice(list(fields)))
            return "out_of_range", json.dumps({"cmd": chosen, **fields[chosen]}).encode()
        if how == 7:
            return "huge", json.dumps({"cmd": "ping", "pad": "x" * int(self.rng.integers(8000, 60000))}).encode()
        return "odd_id", json.dumps({"cmd": "ping", "id": self._bad()}).encode()
