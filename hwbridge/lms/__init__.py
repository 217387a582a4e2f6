"""SICK LMS 2xx serial telegrams: codec and model."""
