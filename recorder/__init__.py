"""The recorder: everything on the bus into one MCAP file (JSON messages, one channel per topic)."""
