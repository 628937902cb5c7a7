"""The simulated instruments: the twin's side of every device hexatherm drives, in a room
of their own (as ``ophyd.sim`` is), so that the drivers a lab runs on its machines
(:mod:`hexatherm.devices`) read apart from what they are rehearsed and tested against.

- :mod:`.ipp`: an I++ DME server measuring the twin's balls (``serve-twin``);
- :mod:`.symetrie`: a Symétrie controller (API v2 text protocol) moving the twin's hexapod;
- :mod:`.symetriepmac`: a Symétrie controller of the gpascii dialect;
- :mod:`.pi`: a PI C-887 controller (GCS over TCP);
- :mod:`.thermocouples`: a thermocouple logger;
- :mod:`.tcpservice`: the small TCP server they share.

Nothing in a lab's run imports them; ``serve-twin`` and the tests do.
"""
