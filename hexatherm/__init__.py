"""hexatherm: thermal deflection decoupled 6-DOF pose measurement of hexapods."""

__version__ = "0.1.0"
