"""``python -m hexatherm``: the command line, as the ``hexatherm`` script."""

from __future__ import annotations

from hexatherm.cli import main

if __name__ == "__main__":
    main(prog_name="hexatherm")
