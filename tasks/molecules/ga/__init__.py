"""An LLM-free proposer for the molecule tasks: a graph-based genetic algorithm.

After Jensen's graph-based GA (Chem. Sci. 10, 3567, 2019): children come from atom, bond and
ring mutations (``mutations``) and from fragment exchange between two parents (``crossover``) on
RDKit molecular graphs; ``graph`` holds the editable form and the filters every child passes,
``conformer`` the ETKDG + MMFF coordinates, ``proposer`` the :class:`GraphGAProposer` a task
offers as its built-in proposer. Everything random derives from one seed.
"""

from tasks.molecules.ga.proposer import GraphGAProposer

__all__ = ["GraphGAProposer"]
