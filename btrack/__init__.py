"""btrack: distributed boundary tracking with workload and phase balancing."""
