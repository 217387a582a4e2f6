"""Laser localisation: one particle filter per robot (thesis ch. 5, 6.1.5)."""
