#!/usr/bin/env python3
"""Line following on the floor sensors: a dark line on a light floor, between the front pair.

Asks for the floor sensors every 20 ms. The two front sensors straddle the line; the difference
of their readings steers (the one that sees more white is the side the robot drifts to), damped by
how fast that difference changes, and the robot slows while it is off centre. When both see white
it has lost the line and turns on the spot towards the side it last saw it on.

A motor command follows every new floor reading (and at least every 100 ms, well inside the
DiWheelDrive's 500 ms dead-man).

Lock-step (the emulated robot starts it):  --controller "python3 examples/line_following.py"
Live:  python3 examples/line_following.py --slcan /dev/pts/N
"""

from amiro_behaviour import FLOOR_PROXIMITY, floor_reading, main, motor, publish

BLACK = 5_900         # counts on black (the floor sensors' measured curve: docs/world.md)
WHITE = 37_600        # counts on white
SPEED_M_S = 0.40      # on the line's centre
SLOW_OFF_CENTRE = 0.5  # the speed's share given up at a full black/white difference
STEER_RAD_S = 2.0     # turn rate at a full black/white difference
DAMP_S = 0.02         # turn rate per rate of change of the difference (derivative time)
SEARCH_RAD_S = 2.5
KEEPALIVE_S = 0.10


def whiteness(counts):
    """0 on black, 1 on white."""
    return min(1.0, max(0.0, (counts - BLACK) / (WHITE - BLACK)))


class LineFollowing:
    def __init__(self):
        self.floor = None
        self.fresh = False        # a floor reading came since the last command
        self.last_side = 0.0      # > 0: the line was last seen to the left
        self.error = None         # the last difference and when it was seen
        self.error_t = None
        self.last_motor = None

    def start(self):
        return [publish(FLOOR_PROXIMITY, 20)]

    def on_message(self, msg):
        reading = floor_reading(msg)
        if reading is not None:
            self.floor = reading
            self.fresh = True

    def decide(self, t):
        if self.floor is None:
            return 0.0, 0.0
        front_right, _, _, front_left = self.floor
        left, right = whiteness(front_left), whiteness(front_right)
        if left > 0.8 and right > 0.8:
            # Lost: turn on the spot towards where the line was.
            self.error = None
            return 0.0, SEARCH_RAD_S if self.last_side >= 0 else -SEARCH_RAD_S
        error = left - right          # > 0: the left sensor is off the line, the line is to the right
        rate = 0.0
        if self.error is not None and t > self.error_t:
            rate = (error - self.error) / (t - self.error_t)
        self.error, self.error_t = error, t
        if abs(error) > 0.1:
            self.last_side = -error
        forward = SPEED_M_S * (1.0 - SLOW_OFF_CENTRE * abs(error))
        return forward, -STEER_RAD_S * (error + DAMP_S * rate)

    def tick(self, t):
        keepalive = self.last_motor is None or t - self.last_motor >= KEEPALIVE_S - 1e-9
        if not (self.fresh or keepalive):
            return []
        self.fresh = False
        self.last_motor = t
        return [motor(*self.decide(t))]


if __name__ == "__main__":
    main(LineFollowing(), __doc__.splitlines()[0])
