"""The last metre to the motors: BL-Ctrl 2.0 ESCs on I2C, without rclpy.

- protocol: set-point encoding (one byte, or 11 bits in two), telemetry decoding, and what the
  state byte means;
- bus: the buses: Linux i2c-dev through smbus2, and a recording bus with injected faults (tests);
- virtual: a virtual ESC bus in shared memory: the ESC node writes it as it would the I2C bus,
  and the sim reads the set points from it (and answers the telemetry);
- driver: what the ESC node decides: zero at start and stop, the command watchdog, retries and
  error counts, the probe at start-up, the motor test;
- health: the node's diagnostics, typed, and the one table of their keys.
"""
