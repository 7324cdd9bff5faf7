"""Genetic programming over constitutive laws: generated code passes the proposal checks and
runs with finite values and gradients, the grammar can express the laws in play (written here
by hand, never handed to the search), and proposals are reproducible."""

import ast
import math
import random
import re
from pathlib import Path

import pytest
import torch

from bridges import laws as torch_laws
from bridges.linalg import stable_linalg
from sga_agent.parsing import check_candidate, parse_response
from sga_agent.registry import load_task
from sga_agent.runner import task_options
from sga_agent.task import BuiltinProposer, EvaluationSettings, Parent
from tasks.constitutive import prompt_text
from tasks.constitutive.gp import GeneticProgrammingProposer, grammar
from tasks.constitutive.gp.canonical import form
from tasks.constitutive.gp.codegen import genome_from_code, law_code, parameter_names, with_values
from tasks.constitutive.gp.enumeration import elastic_pairs, loose_form, small_forms
from tasks.constitutive.gp.genome import (
    Genome,
    Node,
    Param,
    Term,
    fits,
    params,
    random_genome,
    random_term,
)
from tasks.constitutive.gp.proposer import (
    CONSTANT_MOVES,
    DESCRIPTIONS,
    HIGHER_START,
    operator_weights,
)
from tasks.constitutive.gp.seeds import seed_genome
from tasks.constitutive.gp.variation import OPERATORS
from tasks.constitutive.inner import scalar_parameters
from tasks.constitutive.law_code import load_law
from tasks.constitutive.options import ConstitutiveOptions

GP = Path(__file__).resolve().parents[3] / "tasks" / "constitutive" / "gp"
LAWS = Path(__file__).resolve().parents[3] / "examples" / "laws"
KINDS = ("elastic", "plastic")


def deformations(batch: int = 16, spread: float = 0.15, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    noise = torch.randn(batch, 3, 3, generator=generator, dtype=torch.float64)
    return torch.eye(3, dtype=torch.float64) + spread * noise


def run_law(code: str) -> tuple[torch.nn.Module, torch.Tensor]:
    """The law's output on F near the identity (F = I included), after a backward pass."""
    check_candidate(code, load_task("elastic"))
    law = load_law(code, torch.float64)
    F = torch.cat([torch.eye(3, dtype=torch.float64)[None], deformations()])
    with stable_linalg():
        out = law(F)
        if out.requires_grad:  # the identity has no parameters
            out.sum().backward()
    return law, out


def successive_batches(
    proposer: GeneticProgrammingProposer, pool: list[Parent], temperature: float, n: int,
    count: int,
) -> list[list[str]]:
    """``count`` batches of ``n`` answers from ``pool`` at ``temperature``, seeds 0, 1, ...,
    each told the answers of the batches before it (as a search's iterations are)."""
    batches: list[list[str]] = []
    for seed in range(count):
        tried = [answer for batch in batches for answer in batch]
        batches.append(proposer.propose_from(pool, temperature, n, seed=seed, tried=tried))
    return batches


def assert_runs(code: str, kind: str) -> None:
    law, out = run_law(code)
    assert out.shape == (17, 3, 3) and torch.isfinite(out).all()
    if kind == "elastic":
        assert torch.allclose(out, out.transpose(-2, -1))
    for name, parameter in law.named_parameters():
        assert parameter.grad is not None and torch.isfinite(parameter.grad).all(), name


@pytest.mark.parametrize("kind", KINDS)
def test_random_laws_pass_the_checks_and_run_with_finite_gradients(kind):
    rng = random.Random(1)
    for _ in range(60):
        assert_runs(law_code(random_genome(rng, kind)), kind)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("operator", sorted(OPERATORS))
def test_variation_operators_give_valid_laws(kind, operator):
    rng = random.Random(2)
    children = 0
    for _ in range(15):
        parent, other = random_genome(rng, kind), random_genome(rng, kind)
        child = OPERATORS[operator](rng, parent, other, 1.0)
        if child is not None:
            assert fits(child) and child.kind == kind
            assert_runs(law_code(child), kind)
            children += 1
    assert children > 0


def test_rescale_shifts_every_coefficient_by_one_step():
    rng = random.Random(4)
    parent = Genome("elastic", (*random_genome(rng, "elastic").terms, random_term(rng, "elastic")))
    child = OPERATORS["rescale"](rng, parent, parent, 1.0)
    shifts = {
        round(new.coefficient.raw - old.coefficient.raw, 3)
        for old, new in zip(parent.terms, child.terms, strict=True)
    }
    assert len(shifts) == 1 and shifts != {0.0}
    assert [t.expr for t in child.terms] == [t.expr for t in parent.terms]


def test_restart_keeps_the_form_and_draws_every_start_again():
    rng = random.Random(6)
    parent = random_genome(rng, "plastic")
    child = OPERATORS["restart"](rng, parent, parent, 1.0)
    assert form(child) == form(parent)
    old, new = [p.raw for _, _, p in params(parent)], [p.raw for _, _, p in params(child)]
    assert all(a != b for a, b in zip(old, new, strict=True))
    assert OPERATORS["restart"](rng, Genome("plastic"), parent, 1.0) is None


def test_the_plastic_identity_returns_F():
    code = law_code(Genome("plastic"))
    law, out = run_law(code)
    assert torch.equal(out[1:], deformations())
    assert not list(law.parameters())


@pytest.mark.parametrize("kind", KINDS)
def test_genomes_round_trip_through_the_code_comment(kind):
    rng = random.Random(3)
    for _ in range(50):
        genome = random_genome(rng, kind)
        code = law_code(genome)
        assert genome_from_code(code, kind) == genome
        assert genome_from_code(code, "plastic" if kind == "elastic" else "elastic") is None
    broken = code.replace('"terms":[[', '"terms":[[["no_such_op"],')
    assert genome_from_code(broken, kind) is None
    assert genome_from_code(prompt_text.PLASTIC_SEED, kind) is None


# ------------------------------------------------- the families in play, written by hand


def N(op: str, *children) -> Node:
    return Node(op, children)


def log(value: float) -> Param:
    return Param("log", math.log(value))


def certain() -> Param:
    return Param("sigmoid", 40.0)  # a weight of 1 to machine precision


def logit(p: float) -> Param:
    return Param("sigmoid", math.log(p / (1 - p)))


E, NU = 1e6, 0.2
MU, LAM = E / (2 * (1 + NU)), E * NU / ((1 + NU) * (1 - 2 * NU))
EPS, DEV, VOL = N("eps"), N("dev", N("eps")), N("vol", N("eps"))
VON_MISES = N("from_strain", N("add", VOL, N("shrink", DEV, N("const", log(3e4 / (2 * MU))))))
SIN = math.sin(math.radians(25.0))
SAND_SLOPE = (3 * LAM + 2 * MU) / (2 * MU) * math.sqrt(2 / 3) * 2 * SIN / (3 - SIN)
THRESHOLD = N("pos", N("scale", Param("linear", -SAND_SLOPE), N("sum", EPS)))
SAND = N("from_strain", N("add", N("neg", VOL), N("shrink", DEV, THRESHOLD)))
CUBE_ROOT_J = N("exp", N("scale", Param("linear", 1 / 3), N("log_J")))
FLUID = N("smul", CUBE_ROOT_J, N("I"))


def example(name: str) -> torch.nn.Module:
    return load_law((LAWS / name).read_text(), torch.float64)


def neo_hookean_reference():
    mu, lam = math.exp(13.0) / (2 * 1.245), math.exp(13.0) * 0.245 / (1.245 * 0.51)
    genome = Genome(
        "elastic",
        (
            Term(log(mu), N("sub", N("matmul", N("F"), N("T", N("F"))), N("I"))),
            Term(log(lam), N("smul", N("log_J"), N("I"))),
        ),
    )
    return genome, example("neo_hookean.py")


def corotated_reference():
    J_minus_one = N("sub", N("J"), N("const", Param("linear", 1.0)))
    genome = Genome(
        "elastic",
        (
            Term(log(2 * MU), N("matmul", N("sub", N("F"), N("R")), N("T", N("F")))),
            Term(log(LAM), N("smul", N("mul", J_minus_one, N("J")), N("I"))),
        ),
    )
    return genome, torch_laws.FixedCorotated(E, NU, dtype=torch.float64)


def hencky_reference():
    genome = Genome(
        "elastic",
        (
            Term(log(2 * MU), N("spatial", EPS)),
            Term(log(3 * LAM), N("spatial", VOL)),
        ),
    )
    return genome, torch_laws.StVKHencky(E, NU, dtype=torch.float64)


def neo_hookean_with_b():
    genome, reference = neo_hookean_reference()
    b_minus_identity = N("sub", N("b"), N("I"))
    return Genome("elastic", (Term(genome.terms[0].coefficient, b_minus_identity),
                              genome.terms[1])), reference  # fmt: skip


def plastic_reference(name: str, *terms: tuple[Param, Node]):
    return Genome("plastic", tuple(Term(w, expr) for w, expr in terms)), example(name)


REFERENCES = {
    "neo-Hookean": neo_hookean_reference,
    "fixed corotated": corotated_reference,
    "StVK on the Hencky strain": hencky_reference,
    "von Mises": lambda: plastic_reference("von_mises.py", (certain(), VON_MISES)),
    "Drucker-Prager": lambda: plastic_reference("drucker_prager.py", (certain(), SAND)),
    "fluid": lambda: plastic_reference("fluid.py", (certain(), FLUID)),
    "neo-Hookean with b": neo_hookean_with_b,
    "von Mises block": lambda: plastic_reference("von_mises.py", (Param("unit", 1.0), N(
        "from_strain", N("cylinder", EPS, N("const", log(3e4 / (2 * MU)))))),),
    "Drucker-Prager block": lambda: plastic_reference("drucker_prager.py", (Param("unit", 1.2), N(
        "from_strain", N("cone", EPS, N("const", log(SAND_SLOPE))))),),
    "mixture": lambda: plastic_reference(
        "mixture.py", (logit(0.5), VON_MISES), (logit(0.3), SAND), (logit(0.2), FLUID)
    ),
}


@pytest.mark.parametrize("family", list(REFERENCES))
def test_the_grammar_expresses_the_laws_in_play(family):
    genome, reference = REFERENCES[family]()
    assert fits(genome)
    code = law_code(genome)
    assert_runs(code, genome.kind)
    law = load_law(code, torch.float64)
    F = deformations(batch=64, spread=0.1, seed=4)
    with torch.no_grad(), stable_linalg():
        expected, found = reference(F), law(F)
    assert not torch.allclose(F, expected) or genome.kind == "elastic"  # plasticity is active
    # parameters start as float32 tensors, as in any law's code (torch.tensor(value))
    assert torch.allclose(found, expected, rtol=0, atol=1e-5 * expected.abs().max())


def test_a_plastic_weight_reaches_one_and_stops_there():
    """min(raw, 1): from 1 up the correction replaces F, and the fit no longer moves it."""
    correction = N("from_strain", VOL)
    replaced = load_law(law_code(Genome("plastic", (Term(Param("unit", 1.3), correction),))),
                        torch.float64)  # fmt: skip
    blended = load_law(law_code(Genome("plastic", (Term(Param("unit", 0.5), correction),))),
                       torch.float64)  # fmt: skip
    F = deformations(seed=5)
    with stable_linalg():
        full, half = replaced(F), blended(F)
        full.sum().backward()
    target = F + 2 * (half.detach() - F)  # half = F + 0.5 (G - F)
    assert torch.allclose(full.detach(), target, atol=1e-12)
    assert replaced.weight0.grad.item() == 0.0


def test_genomes_of_earlier_releases_read_back():
    """A plastic weight was a sigmoid before: such a genome still resumes, unchanged."""
    old = Genome("plastic", (Term(Param("sigmoid", 2.0), N("from_strain", VOL)),))
    code = law_code(old)
    assert genome_from_code(code, "plastic") == old
    assert "torch.sigmoid(self.logit_weight0)" in code


def test_reshape_op_changes_arity_and_keeps_the_first_child():
    rng = random.Random(2)
    parent = Genome("plastic", (Term(Param("unit", 1.0), N("from_strain", VOL)),))
    shapes = set()
    for _ in range(40):
        child = OPERATORS["reshape_op"](rng, parent, parent, 1.0)
        if child is None:
            continue
        root = child.terms[0].expr
        assert fits(child)
        if root.op == "from_strain":  # the P site was reshaped: its first child kept
            assert root.children[0].children[0] == EPS and root.children[0].op != "vol"
            shapes.add(root.children[0].op)
        else:  # the root was (frame or spatial): its child vol(eps) is kept
            assert root.op in ("frame", "spatial") and root.children[0] == VOL
    assert {"cylinder", "cone"} & shapes and len(shapes) > 3


def test_the_blocks_return_onto_their_surfaces():
    """cylinder: the deviatoric part's norm clamped to the radius, the mean kept; cone: the
    radius is the slope times the compression, and expanded strain returns to 0."""
    strain = 0.1 * torch.randn(200, 3, generator=torch.Generator().manual_seed(1),
                               dtype=torch.float64)  # fmt: skip
    helpers = {}
    for source in grammar.HELPERS.values():
        exec(compile("import torch\n" + source, "<helper>", "exec"), helpers)  # noqa: S102
    radius = torch.full((200, 1), 0.05, dtype=torch.float64)
    returned = helpers["cylinder_return"](strain, radius)
    deviatoric = returned - returned.mean(-1, keepdim=True)
    norms = deviatoric.norm(dim=-1)
    original = (strain - strain.mean(-1, keepdim=True)).norm(dim=-1)
    assert torch.allclose(returned.mean(-1), strain.mean(-1))
    assert torch.allclose(norms, original.clamp(max=0.05), atol=1e-9)
    slope = torch.full((200, 1), 0.5, dtype=torch.float64)
    coned = helpers["cone_return"](strain, slope)
    trace = strain.sum(-1)
    assert torch.equal(coned[trace >= 0], torch.zeros_like(coned[trace >= 0]))
    compressed = trace < 0
    limit = (-0.5 * trace[compressed]).clamp(min=0)
    coned_dev = coned - coned.mean(-1, keepdim=True)
    assert (coned_dev.norm(dim=-1)[compressed] <= limit + 1e-9).all()
    assert torch.allclose(coned.sum(-1)[compressed], trace[compressed])


def test_trivial_and_wasteful_terms_are_not_proposed():
    weight, modulus = Param("sigmoid", 0.0), Param("log", 10.0)
    useless = [
        Genome("plastic", (Term(weight, N("from_strain", EPS)),)),  # F itself
        Genome("elastic", (Term(modulus, N("T", N("I"))),)),  # independent of F
        Genome("elastic", (Term(modulus, N("sub", N("F"), N("F"))),)),
        Genome("elastic", (Term(modulus, N("matmul", N("I"), N("F"))),)),
        Genome("plastic", (Term(weight, N("from_strain", N("neg", N("neg", EPS)))),)),
        Genome("elastic", (Term(modulus, N("spatial", EPS)),) * 2),  # one coefficient would do
        Genome("elastic"),  # no stress at all
    ]
    assert not any(fits(genome) for genome in useless)
    assert fits(Genome("plastic", (Term(weight, N("from_strain", N("neg", EPS))),)))


# --------------------------------------------------------------------------- the proposer


def parents(kind: str, count: int = 5, seed: int = 5) -> list[Parent]:
    rng = random.Random(seed)
    found = [Parent(law_code(random_genome(rng, kind)), float(i + 1)) for i in range(count)]
    seed_law = prompt_text.ELASTIC_SEED if kind == "elastic" else prompt_text.PLASTIC_SEED
    return [*found, Parent(seed_law, 0.5), Parent("not even code", math.inf)]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("temperature", [0.5, 1.0])
def test_proposals_are_valid_answers_and_reproducible(kind, temperature):
    proposer = GeneticProgrammingProposer(kind)
    assert isinstance(proposer, BuiltinProposer) and proposer.name == "builtin:gp"
    answers = proposer.propose_from(parents(kind), temperature, 8, seed=11)
    assert answers == proposer.propose_from(parents(kind), temperature, 8, seed=11)
    assert answers != proposer.propose_from(parents(kind), temperature, 8, seed=12)
    codes = []
    for answer in answers:
        assert answer.count("```python") == 1
        codes.append(parse_response(answer).code)
        assert_runs(codes[-1], kind)
        assert genome_from_code(codes[-1], kind) is not None
    assert len(set(codes)) == len(codes)


def test_the_task_offers_the_proposer_and_it_starts_from_the_seed():
    for name, kind in [("elastic", "elastic"), ("granular", "plastic")]:
        task = load_task(name)
        proposer = task.builtin_proposer()
        assert isinstance(proposer, GeneticProgrammingProposer) and proposer.searched == kind
        for temperature in (0.5, 1.0):
            seeded = [Parent(task.seed_solution(), 1.0)]
            for answer in proposer.propose_from(seeded, temperature, 4, seed=0):
                assert_runs(parse_response(answer).code, kind)
        assert len(proposer.propose_from([], 1.0, 3, seed=0)) == 3
    with pytest.raises(ValueError, match="searched must be"):
        GeneticProgrammingProposer("fluid")


def test_the_elastic_seed_genome_is_the_seed_law():
    """The genome a seed parent stands for computes the seed law's stress (symmetrised)."""
    genome = seed_genome("elastic")
    assert fits(genome) and seed_genome("plastic") == Genome("plastic")
    generated = load_law(law_code(genome), torch.float64)
    seed = load_law(prompt_text.ELASTIC_SEED, torch.float64)
    F = deformations(batch=64, spread=0.1, seed=7)
    with torch.no_grad(), stable_linalg():
        expected, found = seed(F), generated(F)
    expected = (expected + expected.transpose(-2, -1)) / 2
    assert torch.allclose(found, expected, rtol=0, atol=1e-5 * expected.abs().max())


def test_children_start_from_their_parents_fitted_values():
    genome = random_genome(random.Random(3), "elastic")
    fitted = {name: 1.5 + i for i, name in enumerate(parameter_names(genome))}
    law = load_law(law_code(with_values(genome, fitted)), torch.float64)
    assert scalar_parameters(law) == pytest.approx(fitted)
    proposer = GeneticProgrammingProposer("elastic")
    seed_fit = {"log_youngs_modulus": 12.0, "poissons_ratio": 0.3}
    for parent, value in [
        (Parent(law_code(genome), 1.0, fitted), 1.5),
        (Parent(prompt_text.ELASTIC_SEED, 1.0, seed_fit), math.log(math.exp(12.0) / 2.6)),  # mu
    ]:
        raw_values = set()
        for answer in proposer.propose_from([parent], 0.5, 8, seed=0):
            child = genome_from_code(parse_response(answer).code, "elastic")
            raw_values |= {param.raw for _, _, param in params(child)}
        assert any(abs(raw - value) < 1e-4 for raw in raw_values), (value, raw_values)


def shape(genome: Genome) -> list:
    """The genome's structure without its parameter values."""

    def strip(expr):
        if isinstance(expr, Param):
            return expr.transform
        return [expr.op, *map(strip, expr.children)]

    return [strip(term.expr) for term in genome.terms]


def test_low_temperature_exploits_the_best_parent_high_temperature_explores():
    for kind in KINDS:
        assert operator_weights(0.2, kind) == operator_weights(0.5, kind)
        assert operator_weights(0.5, kind)["perturb"] > operator_weights(1.0, kind)["perturb"]
        assert operator_weights(1.0, kind)["crossover"] > operator_weights(0.5, kind)["crossover"]
    pool = parents("plastic", count=6)[:6]
    best = genome_from_code(pool[0].code, "plastic")
    same_shape = {}
    for temperature in (0.5, 1.0):
        answers = GeneticProgrammingProposer("plastic").propose_from(pool, temperature, 40, 7)
        genomes = [genome_from_code(parse_response(a).code, "plastic") for a in answers]
        same_shape[temperature] = sum(shape(g) == shape(best) for g in genomes)
    # exploitation still moves the constants of the best form; exploration only makes new forms
    assert same_shape[0.5] > 10 and same_shape[1.0] == 0


def test_the_canonical_form_ignores_constants_argument_order_and_long_ways_of_writing_F():
    a, b = N("add", N("sigma"), EPS), N("add", EPS, N("sigma"))
    law = Genome("plastic", (Term(logit(0.3), N("frame", a)), Term(logit(0.6), N("F"))))
    same = Genome("plastic", (Term(logit(0.9), N("T", N("T", N("from_strain", EPS)))),
                              Term(logit(0.1), N("frame", b))))  # fmt: skip
    assert form(law) == form(same)
    blend = N("blend", logit(0.2), N("F"), N("R"))
    assert form(Genome("plastic", (Term(logit(0.5), blend),))) == form(
        Genome("plastic", (Term(logit(0.5), N("blend", logit(0.8), N("R"), N("F"))),))
    )
    other = [
        Genome("plastic", (Term(logit(0.3), N("frame", N("sub", EPS, N("sigma")))),)),
        Genome("plastic", (Term(logit(0.3), N("matmul", N("R"), N("F"))),)),
        Genome("plastic", (Term(logit(0.3), N("matmul", N("F"), N("R"))),)),  # no commuting
        Genome("plastic", (Term(logit(0.3), N("frame", N("scale", Param("log", 0.0), EPS))),)),
        Genome("plastic", (Term(logit(0.3), N("frame", N("scale", Param("tanh", 0.0), EPS))),)),
    ]
    assert len({form(genome) for genome in [law, *other]}) == 1 + len(other)


@pytest.mark.parametrize("kind", KINDS)
def test_structural_children_are_new_forms(kind):
    """Every operator but the moves of constants gives a form new to the parents and batch."""
    pool = parents(kind, count=5)
    known = {form(g) for p in pool if (g := genome_from_code(p.code, kind)) is not None}
    answers = GeneticProgrammingProposer(kind).propose_from(pool, 1.0, 30, seed=3)
    moves = [DESCRIPTIONS[name] for name in CONSTANT_MOVES]
    structural = [a for a in answers if not any(move in a for move in moves)]
    forms = [form(genome_from_code(parse_response(a).code, kind)) for a in structural]
    assert len(forms) > 20 and len(set(forms)) == len(forms) and not known & set(forms)


def test_the_search_is_not_handed_the_ground_truth():
    """A sanity check, not a proof: no truth constant or truth parameter in the GP's source,
    and no import of the task's specs or examples. The grammar does name the two textbook
    return mappings it has as blocks (von Mises, Drucker-Prager), whose radius and slope are
    subtrees the search must find and fit."""
    source = "\n".join(path.read_text() for path in GP.glob("*.py")).lower()
    banned = ["3e4", "30000", "25.0", "0.245", "0.535", "0.036", "10.3089", "3.2188", "friction",
              "yield stress", "yield_stress", "hookean"]  # fmt: skip
    assert not [word for word in banned if word in source]
    for path in GP.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = [alias.name for alias in getattr(node, "names", [])]
            for module in [getattr(node, "module", None) or "", *names]:
                if module.startswith(("tasks", "examples", "bridges", "taichi_mpm")):
                    assert module.startswith("tasks.constitutive.gp"), module


@pytest.mark.slow
def test_gp_laws_are_scored_by_the_simulation():
    """Three GP individuals of the granular task through the real inner optimization."""
    task = load_task("granular")
    seeded = [Parent(task.seed_solution(), 1.0)]
    answers = task.builtin_proposer().propose_from(seeded, 1.0, 2, seed=0)
    codes = [law_code(Genome("plastic")), *(parse_response(a).code for a in answers)]
    settings = EvaluationSettings(epochs=1, options=ConstitutiveOptions(steps=100))
    results = [task.evaluate(task.capture(code), settings) for code in codes]
    assert results[0].valid and math.isfinite(results[0].loss)
    for result in results:
        assert result.status in ("ok", "unstable"), result.reason


def test_gp_runs_fit_constants_with_lbfgs_unless_told_otherwise():
    task = load_task("elastic")
    for proposer in ("builtin", "builtin:gp"):
        assert task_options(task, {}, proposer) == ConstitutiveOptions(optimizer="lbfgs")
    given = {"optimizer": "adam", "steps": "50"}
    assert task_options(task, given, "builtin") == ConstitutiveOptions(steps=50, optimizer="adam")
    assert task_options(task, {}, "openai/gpt-4o") == ConstitutiveOptions()  # a model: the task's


@pytest.mark.slow
def test_the_von_mises_form_is_reached_from_a_poor_start():
    """Reachability through the real fit: the von Mises genome, its yield radius starting at
    e^-2 = 0.135 (the truth's 0.036), fitted on the plasticine task as the GP's runs fit (L-BFGS)
    finds the radius: on a 200-step scene, 0.0366 and 1400x below the seed's loss (over the full
    scene: 0.0359, 132x the true law's loss, the rest the term's weight, 0.88 from its start)."""
    task = load_task("plasticine")
    start = N("from_strain", N("add", VOL, N("shrink", DEV, N("const", Param("log", -2.0)))))
    code = law_code(Genome("plastic", (Term(Param("sigmoid", 2.0), start),)))
    options = ConstitutiveOptions(steps=200, optimizer="lbfgs")
    settings = EvaluationSettings(epochs=5, options=options)
    result = task.evaluate(task.capture(code), settings)
    seed = task.evaluate(task.capture(law_code(Genome("plastic"))), settings)
    assert result.status == "ok" and result.loss < seed.loss / 100
    radius = math.exp(next(v for k, v in result.parameters.items() if k.startswith("log_k")))
    assert radius == pytest.approx(3e4 / (2 * MU), rel=0.2)


# ------------------------------------------------- enumeration and the run's memory


def test_small_forms_are_distinct_nontrivial_and_hold_the_textbook_blocks():
    listed = small_forms("plastic")
    assert len(listed) == 40 and listed == small_forms("plastic")
    assert len({loose_form(g) for g in listed}) == len(listed)
    assert all(fits(g) and len(g.terms) == 1 for g in listed)
    roots = [g.terms[0].expr for g in listed]
    blocks = [e.children[0].op for e in roots if e.op == "from_strain" and e.children[0].children]
    assert {"cylinder", "cone", "vol", "dev"} <= set(blocks)


def test_explore_children_try_the_untried_small_forms_in_order():
    proposer = GeneticProgrammingProposer("plastic")
    seed = [Parent(prompt_text.PLASTIC_SEED, 1.0)]
    first = proposer.propose_from(seed, 1.0, 12, seed=1)
    second = proposer.propose_from(seed, 1.0, 12, seed=2, tried=first)
    rank = re.compile(r"tried small form (\d+) in order")
    ranks = [[int(m.group(1)) for a in batch if (m := rank.search(a))] for batch in (first, second)]
    assert len(ranks[0]) >= 6 and ranks[0] == sorted(ranks[0]) and ranks[0][0] == 1
    assert not set(ranks[0]) & set(ranks[1]) and min(ranks[1]) > max(ranks[0])
    exploiting = proposer.propose_from(seed, 0.5, 12, seed=1)
    assert not any(rank.search(a) for a in exploiting)
    assert not any(rank.search(a) for a in GeneticProgrammingProposer("elastic").propose_from(
        [Parent(prompt_text.ELASTIC_SEED, 1.0)], 1.0, 12, seed=1))  # fmt: skip


def test_structural_children_are_new_to_the_whole_run():
    """A form evaluated earlier (an answer in ``tried``) is not proposed again, even when no
    parent has it any more."""
    proposer = GeneticProgrammingProposer("plastic")
    pool = parents("plastic")
    earlier = proposer.propose_from(pool, 1.0, 30, seed=3)
    known = {form(genome_from_code(parse_response(a).code, "plastic")) for a in earlier}
    later = proposer.propose_from(pool, 1.0, 30, seed=4, tried=earlier)
    moves = [DESCRIPTIONS[name] for name in CONSTANT_MOVES]
    structural = [a for a in later if not any(move in a for move in moves)]
    forms = {form(genome_from_code(parse_response(a).code, "plastic")) for a in structural}
    assert len(structural) > 20 and not forms & known


def test_the_opening_tries_every_small_form_in_order_replacing_F_and_slopes_twice():
    """In the search's opening each child is the next untried small form, its correction
    replacing F (weight 1); a form with a positive constant comes a second time, from higher
    constants; elastic pairs come in order too."""
    proposer = GeneticProgrammingProposer("plastic")
    seed = [Parent(prompt_text.PLASTIC_SEED, 1.0)]
    answers = proposer.propose_from(seed, 1.0, 40, seed=1, opening=True)
    rank = re.compile(r"tried small form (\d+) in order[^.]*?(, from higher constants)?\.")
    found = [(int(m.group(1)), bool(m.group(2))) for a in answers if (m := rank.search(a))]
    assert len(found) == 40
    firsts = [r for r, higher in found if not higher]
    assert firsts == list(range(1, len(firsts) + 1))
    genomes = [genome_from_code(parse_response(a).code, "plastic") for a in answers]
    for (_, higher), genome in zip(found, genomes, strict=True):
        assert all(term.coefficient.raw == 1.0 for term in genome.terms)
        logs = [p.raw for _, path, p in params(genome) if path is not None and p.transform == "log"]
        if higher:
            assert logs and all(HIGHER_START[0] <= v <= HIGHER_START[1] for v in logs)
        elif logs:
            assert all(v <= grammar.initial("log", "plastic")[1] for v in logs)
    slopes = [r for r, higher in found if higher]
    cone = next(i for i, g in enumerate(small_forms("plastic"), 1) if "cone" in str(form(g)))
    assert cone in slopes and len(slopes) >= 5
    pairs = GeneticProgrammingProposer("elastic").propose_from(
        [Parent(prompt_text.ELASTIC_SEED, 1.0)], 1.0, 10, seed=1, opening=True)  # fmt: skip
    pair = re.compile(r"tried pair of forms (\d+) in order")
    assert [int(pair.search(a).group(1)) for a in pairs] == list(range(1, 11))


def test_an_unsettled_fit_of_the_best_parent_is_continued_once_by_the_first_exploit_child():
    """The first child at the exploit temperature is the best parent at its fitted values
    while that fit moved a constant and no earlier answer is that law; a settled fit, an
    explore batch or an answer already given is not continued."""
    genome = small_forms("plastic")[16]
    started = law_code(with_values(genome, {"weight0": 1.0, "log_k1": -3.9}))
    best = Parent(started, 1e-6, {"weight0": 0.7, "log_k1": -1.5})
    worse = Parent(prompt_text.PLASTIC_SEED, 1e-4)
    proposer = GeneticProgrammingProposer("plastic")
    first = proposer.propose_from([worse, best], 0.5, 2, seed=0)
    assert "continued the fit of the best parent" in first[0]
    continued = genome_from_code(parse_response(first[0]).code, "plastic")
    assert continued == with_values(genome, {"weight0": 0.7, "log_k1": -1.5})
    assert "continued" not in first[1]
    assert not any("continued" in a for a in proposer.propose_from([worse, best], 1.0, 4, 0))
    again = proposer.propose_from([worse, best], 0.5, 2, seed=1, tried=first)
    assert not any("continued" in a for a in again)
    settled = Parent(started, 1e-6, {"weight0": 1.0, "log_k1": -3.895})
    assert not any("continued" in a for a in proposer.propose_from([settled], 0.5, 2, 0))


def test_the_first_explore_child_combines_the_best_forms_pairs_then_triples():
    """Outside the opening, an explore batch starts with the first untried combination of the
    best distinct parents' terms, each at its fitted value times its share (a plastic weight
    over k, an elastic modulus over k); tried combinations come round no more."""
    forms = [with_values(small_forms("plastic")[i], {"weight0": 0.8}) for i in (0, 3, 7)]
    found = [Parent(law_code(g), loss) for g, loss in zip(forms, (1e-6, 2e-6, 3e-6), strict=True)]
    pool = [*found, Parent(prompt_text.PLASTIC_SEED, 1e-4)]
    proposer = GeneticProgrammingProposer("plastic")
    combined = [genome_from_code(parse_response(answers[0]).code, "plastic")
                for answers in successive_batches(proposer, pool, 1.0, 2, 5)
                if "combined the terms of the best forms" in answers[0]]  # fmt: skip
    expected = [(0, 1), (0, 2), (1, 2), (0, 1, 2)]
    assert [[t.expr for t in g.terms] for g in combined] == [
        [forms[i].terms[0].expr for i in chosen] for chosen in expected]
    for genome, chosen in zip(combined, expected, strict=True):
        assert all(t.coefficient.raw == pytest.approx(0.8 / len(chosen), abs=1e-4)
                   for t in genome.terms)  # fmt: skip
    assert not any("combined" in a for a in proposer.propose_from(pool, 0.5, 4, seed=0))
    assert not any("combined" in a for a in proposer.propose_from(pool, 1.0, 4, 0, opening=True))
    pair = elastic_pairs()[0]
    elastic = [Parent(law_code(with_values(pair, {"log_modulus0": 12.0, "log_modulus1": 11.0})),
                      1e-6), Parent(law_code(with_values(elastic_pairs()[3], {})), 2e-6)]
    answer = GeneticProgrammingProposer("elastic").propose_from(elastic, 1.0, 1, seed=0)[0]
    summed = genome_from_code(parse_response(answer).code, "elastic")
    assert "combined the terms" in answer and len(summed.terms) == 3  # one term in common
    moduli = {term.expr: math.exp(term.coefficient.raw) for term in summed.terms}
    halves = [(pair.terms[0].expr, math.exp(12.0) / 2)]
    assert all(moduli[expr] == pytest.approx(value, rel=1e-3) for expr, value in halves)
