"""Devices: what talks to ports and sockets (serial probe streams, CMMs, hexapod controllers).

No click and no printing here: a device reports through return values and callbacks, and the
workflows decide what the operator sees.
"""
