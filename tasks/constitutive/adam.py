"""Adam for the inner fit, without ``torch.optim``.

The first ``torch.optim`` optimizer a process makes imports torch's compiler stack
(``torch._dynamo``, some 800 modules): over a second and ~70 MB of resident memory in every fit
worker, for a few parameters updated once per epoch. This is the same algorithm, operation for
operation, as ``torch.optim.Adam`` with its CPU defaults (no weight decay, no AMSGrad, one
tensor at a time), so a fit gives the same numbers with either.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch


class Adam:
    """Adam (Kingma & Ba) over ``parameters``; ``zero_grad`` and ``step`` as in ``torch.optim``.

    As there, a parameter's moments and step count advance only on steps where it has a
    gradient.
    """

    def __init__(
        self,
        parameters: Iterable[torch.Tensor],
        lr: float = 1e-3,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
    ) -> None:
        if not lr >= 0 or not 0 <= betas[0] < 1 or not 0 <= betas[1] < 1 or not eps >= 0:
            raise ValueError(f"invalid Adam settings: lr={lr}, betas={betas}, eps={eps}")
        self.parameters = list(parameters)
        self.lr, self.betas, self.eps = lr, betas, eps
        self._moments = [(torch.zeros_like(p), torch.zeros_like(p)) for p in self.parameters]
        self._steps = [0] * len(self.parameters)

    def zero_grad(self) -> None:
        """Drop every parameter's gradient."""
        for parameter in self.parameters:
            parameter.grad = None

    @torch.no_grad()
    def step(self) -> None:
        """One update of every parameter that has a gradient."""
        beta1, beta2 = self.betas
        for index, parameter in enumerate(self.parameters):
            grad = parameter.grad
            if grad is None:
                continue
            first, second = self._moments[index]
            self._steps[index] += 1
            step = float(self._steps[index])
            first.lerp_(grad, 1 - beta1)
            second.mul_(beta2).addcmul_(grad, grad, value=1 - beta2)
            step_size = self.lr / (1 - beta1**step)
            denominator = (second.sqrt() / (1 - beta2**step) ** 0.5).add_(self.eps)
            parameter.addcdiv_(first, denominator, value=-step_size)
