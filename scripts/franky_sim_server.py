"""franky-sim's own server (`franky-sim -s mujoco ...`) with one protocol fix.

franky-sim 1.0.4 answers the robot's Connect command with a two-byte status
(the gripper's reply layout, `<HH`); libfranka's robot reply carries a
one-byte status then the two-byte server version
(research_interface/robot/service_types.h, `Connect::Response`). libfranka
only reads the status, so the mismatch goes unnoticed there; franka-rs also
checks the version, reads 0x0A00 = 2560 instead of 10 and refuses to
connect ("Incompatible library version"). This script sends the robot's
layout and changes nothing else: franky-sim still does all the simulation.
Usage: python franky_sim_server.py -s mujoco --hostname 127.0.0.1
"""

import struct

import franky_sim.franka_server as server_module
from franky_sim.franka_robot_server import FrankaRobotServer
from franky_sim.run_server import main

_gripper_connect = server_module.ConnectCommand.handle


def _connect(self, server, command_type_struct="I"):
    if not isinstance(server, FrankaRobotServer):
        # The gripper's server: its layout is the two-byte one.
        return _gripper_connect(self, server, command_type_struct)
    if server.udp_connected:
        return None
    # Message header, then status (u8, kSuccess) and version (u16).
    payload = struct.pack(
        "<BH", server_module.ConnectStatus.kSuccess.value, server.library_version
    )
    header = server_module.MessageHeader(self.command_type, self.command_id, len(payload))
    self.client_socket.sendall(
        header.to_bytes(command_type_struct=command_type_struct) + payload
    )
    server._setup_udp_connection(self.network_udp_port)
    return None


server_module.ConnectCommand.handle = _connect

if __name__ == "__main__":
    main()
