"""`btrack replay`: a recording put back on the bus (core: what and when; process: the shell)."""
