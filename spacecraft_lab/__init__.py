"""The application layer: command line, experiments, reporting, sweeps.

Built on the three library packages (:mod:`spacecraft_env`,
:mod:`identifiers`, :mod:`controllers`), which never import it.

* :mod:`spacecraft_lab.cli`: the ``spacecraft`` command.
* :mod:`spacecraft_lab.demo`: the rendered environment demo.
* :mod:`spacecraft_lab.identification`: the paper's identification
  experiment (reproduction of its Tables 3-5) and the identify sweep task.
* :mod:`spacecraft_lab.control`: the closed-loop comparison (the main job)
  and the control sweep task.
* :mod:`spacecraft_lab.training`: stable-baselines3 agents with and without
  identified-model features; :mod:`spacecraft_lab.agents`: saved agents
  scored beside the LQGs; :mod:`spacecraft_lab.adaptation`: what the
  identifier is worth to an agent (RMA-style).
* :mod:`spacecraft_lab.paper`: the source paper's published figures.
* :mod:`spacecraft_lab.reporting`, :mod:`spacecraft_lab.plots`: tables and
  figures.
* :mod:`spacecraft_lab.sweeps`: Monte-Carlo grids on a process pool or Ray.
"""

from spacecraft_conventions import __version__

__all__ = ["__version__"]
