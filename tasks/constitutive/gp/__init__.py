"""Genetic programming over constitutive-law code: the LLM-free proposer of these tasks.

``grammar`` holds the typed tensor building blocks, ``genome`` the expression trees built from
them, ``variation`` the mutation and crossover operators, ``codegen`` the translation of a
genome into a ``Physics`` module (and back, through a comment), ``canonical`` the key of a
genome's form (so one form is evaluated once), ``enumeration`` the small forms in order of
their prior probability (tried before random ones) and ``proposer`` the
:class:`sga_agent.task.BuiltinProposer`. Pure Python: nothing here imports torch.
"""

from tasks.constitutive.gp.proposer import GeneticProgrammingProposer

__all__ = ["GeneticProgrammingProposer"]
