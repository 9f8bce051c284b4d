#!/usr/bin/env python3
"""Line following on the floor sensors: a dark line on a light floor, between the front pair.

Asks for the floor sensors every 20 ms. The two front sensors straddle the line; the difference
of their readings steers (the one that sees more white is the side the robot drifts to), and when
both see white the robot has lost the line and turns towards the side it last saw it on.

Lock-step (the emulated robot starts it):  --controller "python3 examples/line_following.py"
Live:  python3 examples/line_following.py --slcan /dev/pts/N
"""

from amiro_behaviour import FLOOR_PROXIMITY, floor_reading, main, motor, publish

BLACK = 5_900         # counts on black (the floor sensors' measured curve: docs/world.md)
WHITE = 37_600        # counts on white
SPEED_M_S = 0.10
STEER_RAD_S = 3.0     # turn rate at a full black/white difference
SEARCH_RAD_S = 2.5
MOTOR_EVERY_S = 0.05


def whiteness(counts):
    """0 on black, 1 on white."""
    return min(1.0, max(0.0, (counts - BLACK) / (WHITE - BLACK)))


class LineFollowing:
    def __init__(self):
        self.floor = None
        self.last_side = 0.0      # > 0: the line was last seen to the left
        self.last_motor = None

    def start(self):
        return [publish(FLOOR_PROXIMITY, 20)]

    def on_message(self, msg):
        reading = floor_reading(msg)
        if reading is not None:
            self.floor = reading

    def decide(self):
        if self.floor is None:
            return 0.0, 0.0
        front_right, _, _, front_left = self.floor
        left, right = whiteness(front_left), whiteness(front_right)
        if left > 0.8 and right > 0.8:
            # Lost: turn on the spot towards where the line was.
            return 0.0, SEARCH_RAD_S if self.last_side >= 0 else -SEARCH_RAD_S
        error = left - right          # > 0: the left sensor is off the line, the line is to the right
        if abs(error) > 0.1:
            self.last_side = -error
        return SPEED_M_S * (1.0 - 0.5 * abs(error)), -STEER_RAD_S * error

    def tick(self, t):
        if self.last_motor is not None and t - self.last_motor < MOTOR_EVERY_S - 1e-9:
            return []
        self.last_motor = t
        return [motor(*self.decide())]


if __name__ == "__main__":
    main(LineFollowing(), __doc__.splitlines()[0])
