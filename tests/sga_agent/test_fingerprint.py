"""Fingerprints: equal for the same code in another form, different for other code."""

import pytest

from sga_agent.fingerprint import fingerprint

LAW = '''
import torch


class Physics(torch.nn.Module):
    """A linear elastic law."""

    def __init__(self, youngs_modulus: float = 1e5) -> None:
        super().__init__()
        self.E = torch.nn.Parameter(torch.tensor(youngs_modulus))  # stiffness

    def forward(self, F):
        return self.E * (F - torch.eye(3))
'''

SAME_LAW = """import torch
class Physics(torch.nn.Module):
    def __init__(self, youngs_modulus: float=1e5) -> None:
        "Another docstring."
        super().__init__()
        self.E = torch.nn.Parameter(torch.tensor(youngs_modulus))
    def forward(self, F):
        # comments do not matter
        return (self.E * (F - torch.eye(3)))
"""


def test_form_does_not_change_the_fingerprint():
    assert fingerprint(LAW) == fingerprint(SAME_LAW)
    assert fingerprint("s = 'a'") == fingerprint('s = "a"')
    assert fingerprint("def f():\n    'only a docstring'\n") == fingerprint("def f():\n    pass\n")


@pytest.mark.parametrize(
    "changed",
    [
        LAW.replace("1e5", "2e5"),  # a literal
        LAW.replace("F - torch.eye(3)", "torch.eye(3) - F"),  # structure
        LAW.replace("self.E", "self.mu"),  # a name
        LAW.replace("1e5", "100000"),  # float vs int
    ],
)
def test_behaviour_changes_the_fingerprint(changed):
    assert fingerprint(changed) != fingerprint(LAW)


def test_unparsable_text_is_compared_with_whitespace_collapsed():
    broken = "def law(:\n    return  1"
    assert fingerprint(broken) == fingerprint("def law(:  return 1\n")
    assert fingerprint(broken) != fingerprint("def law(:\n    return 2")
    assert fingerprint("x = '\0'") != fingerprint("")  # null bytes do not parse


def test_fingerprint_is_a_sha256_hex_digest():
    digest = fingerprint(LAW)
    assert len(digest) == 64 and int(digest, 16) >= 0
