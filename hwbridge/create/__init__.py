"""iRobot Open Interface (Create at 57600 baud, Create 2 at 115200): codec and model."""
