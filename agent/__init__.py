"""One robot's controller: a pure core (partition, phase, patrol) and a thin process."""
