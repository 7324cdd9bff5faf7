"""Short source positions for registered folders: errors still name the file, line and code;
kernels elsewhere keep Taichi's positions with carets; the hook is installed by
``taichi_mpm.init``, never by an import."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest
import taichi as ti

from taichi_mpm.front_end import shorten_positions_under

BROKEN_KERNEL = """\
import taichi as ti


@ti.kernel
def broken(out: ti.types.ndarray()):
    for i in range(out.shape[0]):
        out[i] = {name} + 1.0
"""


def _broken_kernel(folder: Path, module_name: str):
    """A kernel in ``folder`` that names an undefined variable on its line 7."""
    folder.mkdir()
    path = folder / f"{module_name}.py"
    path.write_text(BROKEN_KERNEL.format(name=f"undefined_in_{module_name}"))
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    spec.loader.exec_module(module)
    return module.broken, path


def _compile_error(kernel) -> str:
    with pytest.raises(ti.TaichiCompilationError) as caught:
        kernel(ti.ndarray(ti.f64, shape=4))
    return str(caught.value)


def test_a_registered_folder_gets_file_line_and_source_without_carets(tmp_path):
    kernel, path = _broken_kernel(tmp_path / "registered", "front_end_short")
    shorten_positions_under(path.parent)
    message = _compile_error(kernel)
    assert f'File "{path}", line 7, in broken' in message
    assert "out[i] = undefined_in_front_end_short + 1.0" in message
    assert "^" not in message


def test_other_folders_keep_taichis_carets(tmp_path):
    shorten_positions_under(tmp_path / "registered")
    kernel, path = _broken_kernel(tmp_path / "elsewhere", "front_end_full")
    message = _compile_error(kernel)
    assert "line 7" in message and "undefined_in_front_end_full" in message
    assert "^^^" in message


NOTHING_AT_IMPORT = """
import json

from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
from taichi.lang.kernel_impl import Kernel

def hooks():
    return [ASTTransformerContext.get_pos_info, Kernel.__call__, Kernel.materialize]

before = hooks()
import bridges.kernels, bridges.scalar_law, taichi_mpm, taichi_mpm.kernels
imported = hooks()
taichi_mpm.init(arch="cpu")
started = hooks()
print(json.dumps({"import": imported == before,
                  "init": [a is b for a, b in zip(started, before)]}))
"""


def test_importing_the_project_changes_nothing_in_taichi_and_init_installs_the_hook():
    out = subprocess.run([sys.executable, "-c", NOTHING_AT_IMPORT], capture_output=True,
                         text=True, check=True)  # fmt: skip
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result == {"import": True, "init": [False, True, True]}
