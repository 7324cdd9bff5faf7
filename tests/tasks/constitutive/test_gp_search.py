"""A small LLM-free search on the granular task improves on the seed law (the built-in
proposers are a real search). Evaluated in-process (the test session runs Taichi in float64);
the sandbox has its own tests."""

from concurrent.futures import Future

from sga_agent.config import SearchConfig
from sga_agent.registry import load_task
from sga_agent.run_store import RunStore
from sga_agent.search import Search


class InProcess:
    """Evaluator double: the task's own evaluate, here, one at a time."""

    def __init__(self, task) -> None:
        self.task = task

    def submit(self, task, solution, settings):
        future = Future()
        future.set_result(self.task.evaluate(solution, settings))
        return future


def test_small_gp_search_beats_the_seed(tmp_path):
    task = load_task("granular")
    config = SearchConfig(
        task="granular", proposer="builtin", iterations=1, top_k=4, exploit=1, explore=3,
        epochs=2, learning_rate=0.1, task_options={"steps": 200}, workers=1, seed=0,
    )  # fmt: skip
    store = RunStore.create(tmp_path, config, {})
    result = Search(config, task, task.builtin_proposer(), InProcess(task), store).run()
    seed = next(entry for entry in result.heap.entries if entry.candidate == "00-seed")
    assert result.best.candidate != "00-seed"
    assert result.best.loss < seed.loss / 10
