"""The Foxglove view of a run: its scene, recorded (convert) or drawn (render)."""
