#!/usr/bin/env python3
"""Obstacle avoidance on the proximity ring, with the LightRing pointing at the nearest obstacle.

Asks for the ring every 60 ms, drives forward at up to 0.15 m/s and turns away from what the
front half of the ring sees (a Braitenberg-style rule: the closer side pushes harder); when
something is close ahead it turns on the spot, always the same way until the way is clear, so it
does not dither in a corner. The LED nearest the closest obstacle glows red, brighter the closer
it is; with nothing within 200 mm the ring is dark. Only LEDs that change are sent, at most ten times a
second, so a change is one or two frames on the bus.

Lock-step (the emulated robot starts it):  --controller "python3 examples/obstacle_avoidance.py"
Live:  python3 examples/obstacle_avoidance.py --slcan /dev/pts/N
"""

from amiro_behaviour import PROXIMITY_RING, RING_TO_LED, led, main, motor, publish, ring_reading

FAR_MM = 200          # the ring's "nothing seen"
STOP_MM = 70          # something this close ahead: turn on the spot
SLOW_MM = 160         # ahead within this: slow down
CRUISE_M_S = 0.15
TURN_RAD_S = 2.0
MOTOR_EVERY_S = 0.05  # keep-alive well inside the drive's 500 ms dead-man
LIGHTS_EVERY_S = 0.1  # the LEDs change at most ten times a second


class ObstacleAvoidance:
    def __init__(self):
        self.mm = [FAR_MM] * 8
        self.turning = 0          # +1 left, -1 right while escaping, 0 cruising
        self.last_motor = None
        self.shown = ((0, 0, 0),) * 8  # the LED picture last sent (the LightRing starts dark)
        self.last_lights = None

    def start(self):
        return [publish(PROXIMITY_RING, 60)]

    def on_message(self, msg):
        reading = ring_reading(msg)
        if reading is not None:
            index, mm = reading
            self.mm[index] = mm

    def decide(self):
        """(forward m/s, angular rad/s) from the ring."""
        mm = self.mm
        ahead = min(mm[3], mm[4])
        left = min(mm[2], mm[3])
        right = min(mm[4], mm[5])
        if ahead < STOP_MM or (self.turning and ahead < SLOW_MM):
            if not self.turning:
                self.turning = 1 if left >= right else -1
            return 0.0, self.turning * TURN_RAD_S
        self.turning = 0
        speed = CRUISE_M_S * min(1.0, max(0.2, (ahead - STOP_MM) / (SLOW_MM - STOP_MM)))
        # Turn away from the nearer side, harder the nearer it is.
        push = (FAR_MM - right) - (FAR_MM - left)
        return speed, TURN_RAD_S * push / FAR_MM

    def lights(self):
        nearest = min(range(8), key=lambda i: self.mm[i])
        if self.mm[nearest] >= FAR_MM:
            return ((0, 0, 0),) * 8
        glow = 64 + int(191 * (FAR_MM - self.mm[nearest]) / FAR_MM)
        picture = [(0, 0, 0)] * 8
        picture[RING_TO_LED[nearest] - 1] = (glow, 0, 0)
        return tuple(picture)

    def tick(self, t):
        out = []
        if self.last_motor is None or t - self.last_motor >= MOTOR_EVERY_S - 1e-9:
            out.append(motor(*self.decide()))
            self.last_motor = t
        if self.last_lights is not None and t - self.last_lights < LIGHTS_EVERY_S - 1e-9:
            return out
        picture = self.lights()
        if picture != self.shown:
            self.last_lights = t
            for number, rgb in enumerate(picture, start=1):
                if self.shown[number - 1] != rgb:
                    out.append(led(number, rgb))
            self.shown = picture
        return out


if __name__ == "__main__":
    main(ObstacleAvoidance(), __doc__.splitlines()[0])
