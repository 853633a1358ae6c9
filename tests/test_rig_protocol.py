"""The rig's serial protocol (docs/rig-protocol.md): wire format, round trips over pyserial,
timeouts, garbled replies and retries that do not execute a command twice."""

from __future__ import annotations

import pytest

from rig.client import RigClient, Timing
from rig.errors import DeviceGarbled, DeviceRefused, DeviceReset, DeviceTimeout
from rig.sim import SimulatedDevice, SimulatedRigServer
from rig.transport import SerialTransport
from rig.wire import (Command, Reply, WireError, checksum, format_command, format_reply, frame,
                      parse_command, parse_reply)

FAST = Timing(timeout_s=0.15, turn_timeout_s=0.3, shoot_margin_s=0.2, retries=2)


def test_checksum_is_nmea_xor():
    # NMEA 0183's own example sentence body and checksum.
    assert checksum("GPGLL,5057.970,N,00146.110,E,142451,A") == "27"
    assert frame("1 ID") == f"1 ID*{checksum('1 ID')}\n"


def test_wire_round_trip_and_damage():
    cmd = Command(417, "LED", ("2", "5", "255"))
    assert parse_command(format_command(cmd)) == cmd
    reply = Reply("OK", 417, "9", {"angle": "45.00"})
    assert parse_reply(format_reply(reply)) == reply
    err = Reply("ERR", 3, "9", reason="range level 300 outside 0..255")
    assert parse_reply(format_reply(err)) == err
    hello = Reply("HELLO", 0, "10", {"name": "dome"})
    assert parse_reply(format_reply(hello)) == hello
    line = format_reply(reply)
    flipped = line[:3] + chr(ord(line[3]) ^ 1) + line[4:]
    with pytest.raises(WireError, match="checksum"):
        parse_reply(flipped)
    with pytest.raises(WireError):
        parse_reply("OK 417 boot=9\n")  # no checksum at all
    with pytest.raises(WireError):
        frame("x" * 200)


def test_loop_url_carries_lines():
    """The transport is plain pyserial: ``loop://`` echoes a line back whole."""
    t = SerialTransport("loop://")
    t.write_line(frame("1 ID"))
    assert t.read_line(0.5) == frame("1 ID")
    assert t.read_line(0.05) is None
    t.close()


@pytest.fixture
def device():
    return SimulatedDevice(boards=2, leds_per_board=4)


def _client(server: SimulatedRigServer, timing: Timing = FAST) -> RigClient:
    return RigClient(SerialTransport(server.url), timing, first_seq=100)


def test_round_trip_over_a_socket_port(device):
    with SimulatedRigServer(device) as server:
        client = _client(server)
        who = client.connect()
        assert (who.name, who.boards, who.leds_per_board) == ("sim-dome", 2, 4)
        client.turn(400.5)  # sent modulo a revolution
        client.led(1, 3, 128)
        client.global_light(20)
        st = client.status()
        assert (st.angle_deg, st.global_level, st.lit) == (40.5, 20, {(1, 3): 128})
        client.dark()
        assert client.status().lit == {}
        with pytest.raises(DeviceRefused, match="range"):
            client.led(2, 0, 255)  # no board 2
        client.close()
    assert client.retries_used == 0


def test_silence_raises_a_timeout_naming_port_and_command(device):
    with SimulatedRigServer(device) as server:
        client = _client(server)
        client.connect()
        device.faults.silent_from = device.received + 1
        with pytest.raises(DeviceTimeout) as info:
            client.led(0, 1, 255)
        client.close()
    message = str(info.value)
    assert server.url in message and "LED 0 1 255" in message and "stopped answering" in message
    assert device.received == 2 + FAST.retries  # ID, then every attempt of the LED command


def test_a_garbled_reply_is_retried_and_the_command_runs_once(device):
    device.faults.garble = {2, 4}  # the replies to the first SHOOT and to the first TURN attempt
    with SimulatedRigServer(device) as server:
        client = _client(server)
        client.connect()
        client.shoot(0.01)
        client.turn(90)
        client.close()
    assert client.retries_used == 2
    assert device.shots == [10]  # the resent SHOOT was answered from memory, not fired again
    assert [c.split()[1] for c in device.executed] == ["ID", "SHOOT", "TURN"]


def test_replies_garbled_every_time_are_reported(device):
    device.faults.garble = set(range(2, 20))
    with SimulatedRigServer(device) as server:
        client = _client(server)
        client.connect()
        with pytest.raises(DeviceGarbled) as info:
            client.global_light(255)
        client.close()
    assert server.url in str(info.value) and "GLOBAL 255" in str(info.value)
    assert "garbled" in str(info.value)


def test_a_garbled_command_is_refused_by_the_device_and_resent(device):
    with SimulatedRigServer(device) as server:
        client = _client(server)
        client.connect()
        # Corrupt the next line on its way out, once, as line noise would.
        write = client.transport.write_line
        state = {"done": False}

        def noisy(line: str) -> None:
            if not state["done"]:
                state["done"] = True
                line = line.replace("LED", "LFD")
            write(line)

        client.transport.write_line = noisy  # type: ignore[method-assign]
        client.led(0, 0, 7)
        assert client.status().lit == {(0, 0): 7}
        client.close()
    assert client.retries_used == 1


def test_a_restart_is_detected_from_the_boot_id(device):
    device.faults.reset_at = {3}
    with SimulatedRigServer(device) as server:
        client = _client(server)
        client.connect()
        client.turn(30)
        with pytest.raises(DeviceReset) as info:
            client.status()
        assert (info.value.old_boot, info.value.new_boot) == ("1", "2")
        assert client.status().angle_deg == 0.0  # the restart lost the turn
        client.close()


@pytest.mark.skipif(not hasattr(__import__("os"), "openpty"), reason="POSIX pseudo-terminals")
def test_round_trip_over_a_pseudo_terminal(device):
    """The same client on a tty path (termios, raw mode), as with a USB serial port."""
    from rig.sim.pty_server import SimulatedPtyServer

    device.faults.garble = {3}
    with SimulatedPtyServer(device) as server:
        assert server.url.startswith("/dev/")
        client = _client(server)
        assert client.connect().name == "sim-dome"
        client.turn(12.5)
        client.led(0, 2, 9)
        assert client.status().lit == {(0, 2): 9}
        client.close()
    assert client.retries_used == 1 and device.executed.count("102 LED 0 2 9") == 1


def test_the_documented_contract_matches_the_code():
    """Every command in docs/rig-protocol.md's table is executed by the reference device, and the
    plan examples in the docs are valid plans."""
    import json
    import re
    from pathlib import Path

    from rig.plan import plan_from_dict

    root = Path(__file__).resolve().parents[1]
    doc = (root / "docs" / "rig-protocol.md").read_text(encoding="utf-8")
    table = doc[doc.index("| command | arguments |"):doc.index("Every command sets an absolute state")]
    documented = re.findall(r"^\| `([A-Z]+)` \|", table, flags=re.M)
    assert documented == ["ID", "STATUS", "TURN", "LED", "GLOBAL", "DARK", "SHOOT"]
    sample = {"ID": [], "STATUS": [], "TURN": ["90"], "LED": ["0", "0", "1"], "GLOBAL": ["1"],
              "DARK": [], "SHOOT": ["5"]}
    device = SimulatedDevice(1, 1)
    for seq, name in enumerate(documented, start=1):
        reply = parse_reply(device.handle(format_command(Command(seq, name, tuple(sample[name]))))[0])
        assert reply.kind == "OK", (name, reply)
    for text in (doc, (root / "rig" / "README.md").read_text(encoding="utf-8")):
        block = re.search(r"```json\n(.*?)```", text, flags=re.S).group(1)
        assert plan_from_dict(json.loads(block)).frames()


def test_cli_identify(device, capsys):
    from abs.cli.main import main

    with SimulatedRigServer(device) as server:
        assert main(["rig", "identify", "--port", server.url]) == 0
        out = capsys.readouterr().out
        device.faults.silent_from = device.received + 1
        assert main(["rig", "identify", "--port", server.url, "--timeout", "0.05", "--retries", "0"]) == 3
    assert "sim-dome, firmware sim-1.0, 2 boards x 4 LEDs" in out and "turntable 0 deg" in out
    err = capsys.readouterr().err
    assert server.url in err and "ID" in err and "run the same command" not in err
