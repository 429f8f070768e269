"""RTDE wire format (Universal Robots Real-Time Data Exchange, protocol version 2).

Every message is ``uint16 size`` (big-endian, header included) · ``uint8 type`` · payload.
Types used here: ``V`` request protocol version, ``v`` controller version, ``O`` setup
outputs (``float64 frequency`` + comma-separated names), ``I`` setup inputs
(comma-separated names), ``S`` start, ``P`` pause, ``U`` data package
(``uint8 recipe id`` + values packed big-endian in recipe order), ``M`` text message.

The variable table lists the RTDE variables a UR controller publishes or accepts that
ur_rtde asks for, with their RTDE type names (as in UR's RTDE guide).
"""

from __future__ import annotations

import struct

HEADER = struct.Struct(">HB")

REQUEST_PROTOCOL_VERSION = 86      # 'V'
GET_URCONTROL_VERSION = 118        # 'v'
TEXT_MESSAGE = 77                  # 'M'
DATA_PACKAGE = 85                  # 'U'
SETUP_OUTPUTS = 79                 # 'O'
SETUP_INPUTS = 73                  # 'I'
START = 83                         # 'S'
PAUSE = 80                         # 'P'

#: RTDE type name → struct format (big-endian, no header)
FORMATS = {
    "BOOL": "?", "UINT8": "B", "UINT32": "I", "UINT64": "Q", "INT32": "i", "DOUBLE": "d",
    "VECTOR3D": "3d", "VECTOR6D": "6d", "VECTOR6INT32": "6i", "VECTOR6UINT32": "6I",
}

_OUTPUTS = {
    "timestamp": "DOUBLE", "target_q": "VECTOR6D", "target_qd": "VECTOR6D", "target_qdd": "VECTOR6D",
    "target_current": "VECTOR6D", "target_moment": "VECTOR6D", "actual_q": "VECTOR6D",
    "actual_qd": "VECTOR6D", "actual_current": "VECTOR6D", "joint_control_output": "VECTOR6D",
    "actual_TCP_pose": "VECTOR6D", "actual_TCP_speed": "VECTOR6D", "actual_TCP_force": "VECTOR6D",
    "target_TCP_pose": "VECTOR6D", "target_TCP_speed": "VECTOR6D", "actual_digital_input_bits": "UINT64",
    "joint_temperatures": "VECTOR6D", "actual_execution_time": "DOUBLE", "robot_mode": "INT32",
    "joint_mode": "VECTOR6INT32", "safety_mode": "INT32", "safety_status": "INT32",
    "actual_tool_accelerometer": "VECTOR3D", "speed_scaling": "DOUBLE", "target_speed_fraction": "DOUBLE",
    "actual_momentum": "DOUBLE", "actual_main_voltage": "DOUBLE", "actual_robot_voltage": "DOUBLE",
    "actual_robot_current": "DOUBLE", "actual_joint_voltage": "VECTOR6D",
    "actual_digital_output_bits": "UINT64", "runtime_state": "UINT32", "robot_status_bits": "UINT32",
    "safety_status_bits": "UINT32", "standard_analog_input0": "DOUBLE", "standard_analog_input1": "DOUBLE",
    "standard_analog_output0": "DOUBLE", "standard_analog_output1": "DOUBLE", "ft_raw_wrench": "VECTOR6D",
    "payload": "DOUBLE", "payload_cog": "VECTOR3D", "payload_inertia": "VECTOR6D",
    "output_bit_registers0_to_31": "UINT32", "output_bit_registers32_to_63": "UINT32",
    "elbow_position": "VECTOR3D", "elbow_velocity": "VECTOR3D", "tool_mode": "UINT32",
    "tool_output_voltage": "INT32", "tool_output_current": "DOUBLE", "tool_temperature": "DOUBLE",
    "tcp_force_scalar": "DOUBLE", "actual_qdd": "VECTOR6D", "actual_moment": "VECTOR6D",
}
_OUTPUTS.update({f"output_int_register_{i}": "INT32" for i in range(48)})
_OUTPUTS.update({f"output_double_register_{i}": "DOUBLE" for i in range(48)})

_INPUTS = {
    "speed_slider_mask": "UINT32", "speed_slider_fraction": "DOUBLE",
    "standard_digital_output_mask": "UINT8", "standard_digital_output": "UINT8",
    "configurable_digital_output_mask": "UINT8", "configurable_digital_output": "UINT8",
    "tool_digital_output_mask": "UINT8", "tool_digital_output": "UINT8",
    "standard_analog_output_mask": "UINT8", "standard_analog_output_type": "UINT8",
    "standard_analog_output_0": "DOUBLE", "standard_analog_output_1": "DOUBLE",
    "input_bit_registers0_to_31": "UINT32", "input_bit_registers32_to_63": "UINT32",
    "external_force_torque": "VECTOR6D",
}
_INPUTS.update({f"input_int_register_{i}": "INT32" for i in range(48)})
_INPUTS.update({f"input_double_register_{i}": "DOUBLE" for i in range(48)})


def output_type(name: str) -> str:
    """RTDE type of an output variable, or ``NOT_FOUND`` as a controller answers."""
    return _OUTPUTS.get(name, "NOT_FOUND")


def input_type(name: str) -> str:
    return _INPUTS.get(name, "NOT_FOUND")


def message(kind: int, payload: bytes = b"") -> bytes:
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


def recipe_struct(types) -> struct.Struct:
    return struct.Struct(">" + "".join(FORMATS[t] for t in types))


def pack_values(types, values) -> bytes:
    """Flatten ``values`` (scalars or sequences, one per type) and pack them."""
    flat = []
    for t, v in zip(types, values):
        if t in ("VECTOR3D", "VECTOR6D", "VECTOR6INT32", "VECTOR6UINT32"):
            flat.extend(v)
        else:
            flat.append(v)
    return recipe_struct(types).pack(*flat)


def unpack_values(types, data: bytes) -> list:
    """Inverse of :func:`pack_values`: one value (scalar or tuple) per type."""
    flat = list(recipe_struct(types).unpack(data))
    out = []
    for t in types:
        n = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}.get(t, 1)
        out.append(tuple(flat[:n]) if n > 1 else flat[0])
        del flat[:n]
    return out


def names(payload: bytes) -> list[str]:
    """Comma-separated variable names (ur_rtde sends a trailing comma)."""
    return [n for n in payload.decode("ascii", "replace").split(",") if n]


# ---------------------------------------------------------------- controller state values
DASHBOARD_PORT, SCRIPT_PORT, RTDE_PORT = 29999, 30003, 30004

# runtime_state, robot_mode, safety_mode values (UR RTDE guide)
STOPPED, PLAYING = 1, 2
ROBOT_MODE_RUNNING = 7
SAFETY_NORMAL, SAFETY_PROTECTIVE_STOP = 1, 3
# safety_status_bits
BIT_NORMAL, BIT_PROTECTIVE, BIT_STOPPED_DUE_TO_SAFETY = 1 << 0, 1 << 2, 1 << 10
# robot_status_bits
BIT_POWER_ON, BIT_PROGRAM_RUNNING = 1 << 0, 1 << 1
