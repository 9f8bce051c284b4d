"""The plumbing the example behaviours share: the AMiRo frames they use, built as python-can
messages, and the two ways a behaviour runs — live on a CAN adapter (python-can's ``slcan``
interface on ``cargo xtask robot --slcan``'s port, or a real robot's adapter) or in lock-step with
the emulated robot through the controller protocol on stdin/stdout (docs/world.md).

A behaviour is a class with three methods, and knows nothing of the transport:

- ``start()`` returns the messages to send once at the beginning (publish requests);
- ``on_message(msg)`` is called with every ``can.Message`` heard on the bus;
- ``tick(t)`` is called every 10 ms with the time in seconds and returns the messages to send.

Frame layout (docs/protocol.md, amiro-can's topic table): 11-bit identifier = C/S bit 10 (0 command,
1 sensor data), priority bits 9-8 (0 urgent … 3 low), topic bits 7-0; little-endian payloads.
"""

import argparse
import struct
import sys
import time

import can

URGENT, HIGH, MEDIUM, LOW = 0, 1, 2, 3

FLOOR_PROXIMITY = 0x04
MOTOR = 0x10
LED_1 = 0x11
PROXIMITY_RING = 0x1F

TICK_S = 0.010

# Ring sensor i (the protocol's index) looks where LED ((i + 4) % 8) + 1 sits: sensor 4 and led-1 are
# both front-right (NNE), sensor 3 and led-8 front-left (NNW), and so on round the robot.
RING_TO_LED = [((i + 4) % 8) + 1 for i in range(8)]


def command_id(topic, priority):
    return (priority << 8) | topic


def topic_of(msg):
    """(is sensor data, topic) of a standard frame."""
    return bool(msg.arbitration_id & 0x400), msg.arbitration_id & 0xFF


def publish(topic, period_ms, priority=LOW):
    """Start (or re-time) the topic's publisher: mode 1, sample time u16, unit 0 = ms."""
    return can.Message(
        arbitration_id=command_id(topic, priority),
        data=struct.pack("<BHB", 1, period_ms, 0),
        is_extended_id=False,
    )


def motor(forward_m_s, angular_rad_s, priority=HIGH):
    """Target velocity: forward i32 µm/s, angular i32 µrad/s (counter-clockwise positive)."""
    return can.Message(
        arbitration_id=command_id(MOTOR, priority),
        data=struct.pack("<ii", round(forward_m_s * 1e6), round(angular_rad_s * 1e6)),
        is_extended_id=False,
    )


def led(number, rgb, priority=LOW):
    """Colour of LED ``number`` (1..8)."""
    return can.Message(
        arbitration_id=command_id(LED_1 - 1 + number, priority),
        data=bytes(rgb),
        is_extended_id=False,
    )


def ring_reading(msg):
    """(sensor, mm) from a proximity-ring frame, or None."""
    sensor, topic = topic_of(msg)
    if not sensor or topic != PROXIMITY_RING or len(msg.data) != 3:
        return None
    index, mm = struct.unpack("<BH", bytes(msg.data))
    return (index, mm) if index < 8 else None


def floor_reading(msg):
    """The four floor counts (front-right, right-wheel, left-wheel, front-left), or None."""
    sensor, topic = topic_of(msg)
    if not sensor or topic != FLOOR_PROXIMITY or len(msg.data) != 8:
        return None
    return struct.unpack("<4H", bytes(msg.data))


def cansend(msg):
    """``ID#DATA``, as can-utils writes it."""
    return f"{msg.arbitration_id:03X}#{bytes(msg.data).hex().upper()}"


def parse_candump(line):
    """A ``candump -l`` line ``(T) IFACE ID#DATA`` as a can.Message, or None."""
    parts = line.split()
    if len(parts) != 3 or not parts[0].startswith("(") or "#" not in parts[2]:
        return None
    ident, data = parts[2].split("#", 1)
    return can.Message(
        timestamp=float(parts[0].strip("()")),
        channel=parts[1],
        arbitration_id=int(ident, 16),
        data=bytes.fromhex(data),
        is_extended_id=len(ident) > 3,
    )


def run_lockstep(behaviour, stdin=sys.stdin, stdout=sys.stdout):
    """The controller protocol: frames in as candump lines, ``(T) tick`` → our frames, then ``ok``."""
    started = False
    for line in stdin:
        line = line.strip()
        if line.endswith(" tick"):
            t = float(line.split()[0].strip("()"))
            out = [] if started else list(behaviour.start())
            started = True
            out += behaviour.tick(t)
            for msg in out:
                stdout.write(cansend(msg) + "\n")
            stdout.write("ok\n")
            stdout.flush()
        elif line:
            msg = parse_candump(line)
            if msg is not None:
                behaviour.on_message(msg)


def run_live(behaviour, bus, duration_s=None):
    """On a live bus: every message to the behaviour as it arrives, a tick every 10 ms of wall time."""
    for msg in behaviour.start():
        bus.send(msg)
    begin = time.monotonic()
    next_tick = begin + TICK_S
    try:
        while duration_s is None or time.monotonic() - begin < duration_s:
            msg = bus.recv(timeout=max(0.0, next_tick - time.monotonic()))
            if msg is not None:
                behaviour.on_message(msg)
            now = time.monotonic()
            if now >= next_tick:
                for out in behaviour.tick(now - begin):
                    bus.send(out)
                next_tick += TICK_S
                if next_tick < now:  # fell behind: skip the missed ticks rather than bunch them
                    next_tick = now + TICK_S
    finally:
        bus.send(motor(0.0, 0.0))


def main(behaviour, description):
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--slcan", metavar="PORT",
                        help="run live on an SLCAN adapter (e.g. the port `cargo xtask robot --slcan` prints); "
                             "without it, run in lock-step on stdin/stdout (the controller protocol)")
    parser.add_argument("--bitrate", type=int, default=1_000_000)
    parser.add_argument("--duration", type=float, help="live: stop after this many seconds")
    args = parser.parse_args()
    if args.slcan is None:
        run_lockstep(behaviour)
        return
    with can.Bus(interface="slcan", channel=args.slcan, bitrate=args.bitrate) as bus:
        try:
            run_live(behaviour, bus, args.duration)
        except KeyboardInterrupt:
            pass
