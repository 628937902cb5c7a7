"""What the options every command shares need of the floors below the workflows, so that
the command line (``hexatherm.cli.options``) imports only the workflows (issue 34): the
conformity's decision rules.

Light at import (the command line imports it at start-up): what needs numpy or scipy is
imported when called.
"""

from __future__ import annotations

__all__ = ["decision_rules"]


def decision_rules() -> tuple[str, ...]:
    """The decision rules a conformity statement may follow (ILAC-G8:09/2019), by name."""
    from hexatherm.core.conformity import RULES  # numpy and scipy: not at start-up

    return tuple(RULES)
