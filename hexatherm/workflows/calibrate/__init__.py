"""``hexatherm calibrate``: the hexapod's geometry from thermally decoupled poses."""
