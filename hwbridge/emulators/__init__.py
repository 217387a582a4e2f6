"""Byte-level device emulators (device side of our codecs) and their pseudo-terminals."""
