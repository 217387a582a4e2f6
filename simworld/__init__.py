"""The simulated world: maps, kinematics, sensors, and the lockstep clock process."""
