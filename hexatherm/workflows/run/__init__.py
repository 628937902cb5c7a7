"""``hexatherm run``: an unattended campaign driving the CMM (I++ DME) and the hexapod controller.

- :mod:`.files`: the session's files (I++ transcript with the run's markers, controller log,
  per-step records, points) and the rebuild of ``points.csv`` from the transcript;
- :mod:`.resume`: the state of an interrupted run, rebuilt from its files;
- :mod:`.campaign`: the campaign loop (validate, move, wait in position, probe, fit,
  re-probe, re-measure a reference, stop safely); :mod:`.options` its options and
  results, :mod:`.support` the dry run, :mod:`.cmmfacts` and :mod:`.pace` its helpers.
"""
