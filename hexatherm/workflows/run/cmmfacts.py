"""What ``run`` asks the CMM about itself: the DME version, then only what that version has.

A refused optional query is "unknown" (the server's error cleared, a warning on the screen
and in ``run.yaml``), never the end of a run.
"""

from __future__ import annotations

from typing import Any

from hexatherm.devices.ipp import Call, IppClient, IppEvent
from hexatherm.errors import AcquisitionError
from hexatherm.workflows.run.options import Notify

#: ``Tool.AvrRadius`` came with I++ DME 1.4.2
AVR_RADIUS_SINCE = (1, 4, 2)


def dme_version(cmm: IppClient, notify: Notify) -> dict[str, Any]:
    """``GetDMEVersion()`` (the first query of a session): the facts of ``run.yaml``."""
    facts: dict[str, Any] = {"dme_version": "unknown", "tool_avr_radius_mm": "unknown"}
    facts["unknown"] = []
    version = cmm.dme_version()
    if version is None:
        why = "GetDMEVersion() refused or not a version: optional queries not sent"
        facts["unknown"].append(why)
        notify("warn", f"the CMM's I++ DME version is unknown ({why})")
    else:
        facts["dme_version"] = version[0]
    return facts


def tip_radius(
    cmm: IppClient, facts: dict[str, Any], tool: str, tip_diameter_mm: float, notify: Notify
) -> None:
    """``GetProp(Tool.AvrRadius())`` where the version has it; checked against the balls file."""
    text = str(facts["dme_version"])
    numbers = tuple(int(x) for x in text.split(".")) if text != "unknown" else None
    if numbers is None:
        why = "Tool.AvrRadius not asked (DME version unknown)"
    elif numbers < AVR_RADIUS_SINCE:
        why = f"Tool.AvrRadius not asked (DME {text} has none; it came with 1.4.2)"
    else:
        result, error = cmm.optional("GetProp(Tool.AvrRadius())")
        values = [
            item.args[0]
            for _, data in ([] if result is None else result.data)
            for item in data
            if isinstance(item, Call) and item.name == "Tool.AvrRadius" and len(item.args) == 1
        ]
        if values and isinstance(values[0], float):
            facts["tool_avr_radius_mm"] = values[0]
            if abs(values[0] - 0.5 * tip_diameter_mm) > 1e-3:
                notify(
                    "warn",
                    f"the CMM's tool {tool} has a tip radius of {values[0]:g} mm, "
                    f"the balls file says {0.5 * tip_diameter_mm:g} mm",
                )
            return
        why = f"GetProp(Tool.AvrRadius()) {'refused: ' + str(error) if error else 'no number'}"
    facts["unknown"].append(why)
    notify("warn", f"the CMM's tip radius is unknown: {why}")


def check_tool(cmm: IppClient, tool: str) -> None:
    """The CMM knows ``tool``: listed by ``EnumTools()``, or (a server without it) named by
    ``FoundTool.Name`` after ``FindTool`` (a lax ``FindTool`` says nothing of a tool it
    does not know, and leaves ``FoundTool`` as it was).

    Raises
    ------
    AcquisitionError
        The CMM has no such tool (the tools it has named when listed).
    """
    tools = cmm.enum_tools()
    if tools is not None:
        if tool not in tools:
            raise AcquisitionError(
                f"the CMM has no tool {tool!r} (EnumTools lists {', '.join(tools) or 'none'})"
            )
        return
    cmm.find_tool(tool)
    found = cmm.get_prop("FoundTool.Name")["FoundTool.Name"]
    if tuple(found) != (tool,):
        raise AcquisitionError(f"the CMM has no tool {tool!r} (FoundTool is {found!r})")


def changed_tool(event: IppEvent) -> str | None:
    """The tool an event says the CMM changed to (``E0000 # ChangeTool("RefTool")``: an
    operator's or a tool changer's change), or None.

    >>> from hexatherm.devices.ipp import parse_response
    >>> line = 'E0000 # ChangeTool("RefTool")'
    >>> changed_tool(IppEvent("t", line, parse_response(line)))
    'RefTool'
    """
    response = event.response
    if response is None or response.kind != "#":
        return None
    for item in response.data:
        if isinstance(item, Call) and item.name in ("ChangeTool", "SetTool") and item.args:
            if len(item.args) == 1 and isinstance(item.args[0], str):
                return str(item.args[0])
    return None
