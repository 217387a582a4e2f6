"""Real devices on the btrack bus: iRobot Create / Create 2 (Open Interface) and SICK LMS 2xx.

Layers as in a driver people trust: transport (``transport.py``: bytes in and out of a
pyserial port, reopened when lost), protocol codecs (``create/codec.py``,
``lms/codec.py``: pure incremental parsers and encoders), data models in SI units
(``create/model.py``, ``lms/model.py``), then the bridge processes
(``create_bridge.py``, ``lms_bridge.py``). ``emulators/`` speaks the same protocols
from the device side on pseudo-terminals; ``hil.py`` runs the simulator's physics
behind them (``btrack sim --hil``).
"""
