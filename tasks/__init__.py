"""Scientific task plugins for the SGA bilevel search.

Each task (a simulation setup, its learnable physics and its loss) is a plugin that the agent
discovers through the ``sga_agent.tasks`` entry-point group, so tasks shipped here and tasks from
other distributions are found the same way: :mod:`tasks.constitutive` (constitutive-law
discovery on the differentiable MPM) and :mod:`tasks.molecules` (molecule design with RDKit and
GFN1-xTB).
"""
