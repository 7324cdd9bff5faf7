"""Task-specific prompt text of the constitutive-law tasks (our wording).

The structure follows the paper's prompts: who the model is, what is observed and searched, the
code skeleton a proposal must follow, and rules and tips for the code. The seed laws are read
from ``examples/seeds`` (code the model sees as written, kept where code is kept).
"""

from importlib import resources


def _seed(name: str) -> str:
    """The code of the seed law ``name`` of ``examples/seeds``."""
    return (resources.files(__package__) / "seeds" / name).read_text(encoding="utf-8")


ROLE = (
    "You are an expert in continuum mechanics, material science, physical simulation and "
    "PyTorch, helping to discover constitutive laws from observed motion."
)

SCENE = (
    "A cube of side 0.5 m (1000 material points, density 1000 kg/m^3) starts in the middle of a "
    "1 m box with a linear velocity of (1.0, -0.5, -0.75) m/s and an angular velocity of "
    "(1, 3, 2) rad/s, falls under gravity (9.8 m/s^2 along -y) and hits the box's slip walls. "
    "A differentiable material point method simulates it for 1000 steps of 5e-4 s; every "
    "100 steps the simulation is reset to the observed state. A proposal is scored by the mean "
    "squared distance (m^2) between simulated and observed particle positions over all steps, "
    "after its continuous parameters have been fitted by gradient descent (Adam) through the "
    "simulation."
)

ELASTIC_CONTEXT = (
    SCENE + " The material shows no plasticity. Find the elastic constitutive law: the function "
    "mapping the deformation gradient F to the Kirchhoff stress tau = P F^T (P the first "
    "Piola-Kirchhoff stress), and its material parameters."
)

PLASTIC_CONTEXT = (
    SCENE + " The elastic response is known: St. Venant-Kirchhoff on the Hencky strain with "
    "Young's modulus 1e6 Pa and Poisson's ratio 0.2. Find the plastic part: the return mapping "
    "from the trial deformation gradient F to the corrected deformation gradient, and its "
    "material parameters (the elastic law is then applied to the corrected F)."
)

_TEMPLATE = '''import torch
import torch.nn as nn


class Physics(nn.Module):
    def __init__(self, param: float = DEFAULT_VALUE):
        """Trainable continuous parameters, initialised from the defaults in the signature.

        Args:
            param (float): the physical meaning of the parameter.
        """
        super().__init__()
        self.param = nn.Parameter(torch.tensor(param))

    def forward(self, F: torch.Tensor) -> torch.Tensor:
        """{doc}

        Args:
            F (torch.Tensor): {argument} (B, 3, 3).

        Returns:
            {result} (torch.Tensor): {result_doc} (B, 3, 3).
        """
        return {result}
'''

ELASTIC_TEMPLATE = _TEMPLATE.format(
    doc="Kirchhoff stress from the deformation gradient.",
    argument="deformation gradient",
    result="kirchhoff_stress",
    result_doc="Kirchhoff stress tau = P @ F^T",
)

PLASTIC_TEMPLATE = _TEMPLATE.format(
    doc="Corrected deformation gradient from the trial deformation gradient.",
    argument="trial deformation gradient",
    result="F_corrected",
    result_doc="deformation gradient after the plastic correction",
)

_COMMON_RULES = """\
Code rules:
1. Python with PyTorch only (`torch`, `torch.nn`, `math`); no other import, no file or network
   access.
2. One class `Physics(nn.Module)`: continuous parameters as `nn.Parameter`s created in `__init__`,
   every `__init__` argument with a default value (the starting point of the fit), and the
   symbolic law in `forward(self, F)`. Set the defaults from what earlier fits found.
3. Parameters are fitted with Adam at a learning rate of about 0.03 per epoch: give each a scale
   of order one (for example a modulus as its logarithm, `torch.exp(self.log_E)`).
4. Every tensor is batched: F is (B, 3, 3). Note the shape after each operation in a comment,
   e.g. `# (B, 3, 3)`, and reshape scalars per particle before broadcasting: `J.view(-1, 1, 1)`.
   Each particle's result depends on its own F alone: never reduce over the batch dimension
   (no mean or sum over dim 0), or the law is refused.
5. Batched helpers: trace `A.diagonal(dim1=-2, dim2=-1).sum(-1)` (not `torch.trace`), transpose
   `A.transpose(-2, -1)`, determinant `torch.linalg.det(A)`, identity
   `torch.eye(3, dtype=F.dtype).expand_as(F)`.
6. `torch.linalg.svd(F)` may be used: in the simulator it returns rotations U and Vh
   (det = +1, so the last singular value is negative for an inverted F) and its gradient stays
   finite when singular values coincide. Guard logarithms and divisions (`clamp(min=...)`).
7. The law is recorded as a graph of tensor operations before it is fitted: no Python `if` on a
   tensor's value, no `.item()`, `float()` or NumPy on tensors (use
   `torch.where(condition, a, b)` instead of an if), no random numbers, no in-place writes.
"""

ELASTIC_RULES = _COMMON_RULES + (
    "7. `forward` returns the Kirchhoff stress tau = P @ F^T (B, 3, 3), never P or another stress."
)

PLASTIC_RULES = _COMMON_RULES + (
    "7. `forward` returns the corrected deformation gradient (B, 3, 3). Returning F unchanged "
    "means no plasticity; plasticity is only worth adding when the feedback calls for it."
)

#: The seeds: the laws a search starts from, shown to the model as its first solution. They
#: live in ``examples/seeds``; ``seeds`` here links to it (a wheel holds the files themselves).
ELASTIC_SEED = _seed("linear_elastic.py")
PLASTIC_SEED = _seed("no_plasticity.py")
