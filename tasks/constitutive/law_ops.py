"""Which operations a captured law graph may contain: pure, deterministic tensor math.

A captured law is a graph of ATen operations (see :mod:`tasks.constitutive.law_graph`). The
trusted fit runs only graphs whose every operation is named here. Excluded on purpose: I/O and
anything with side effects, in-place and ``out=`` variants (an overload whose schema mutates an
argument is refused where the graph is built), random numbers (a score must be
reproducible), operations on raw memory (``as_strided``, ``set_``), and uninitialised memory
(``empty`` and friends are run as their zero-filled counterparts instead).
"""

from __future__ import annotations

import operator

#: Version of the graph document (:mod:`tasks.constitutive.law_graph`).
GRAPH_FORMAT = 1
#: What a law may do, for the messages that refuse one.
HINT = (
    "a law may use only pure tensor math on F and its parameters (torch arithmetic, "
    "reductions, reshaping, linear algebra, where/clamp); no random numbers, no in-place "
    "writes into F, no I/O"
)

#: ATen operator packets (``aten.<name>``) allowed with any overload but ``out`` variants.
ATEN_OPS = frozenset(
    {
        "_linalg_check_errors",
        "_linalg_det",
        "_linalg_eigh",
        "_linalg_solve_ex",
        "_linalg_svd",
        "_log_softmax",
        "_softmax",
        "_to_copy",
        "_unsafe_view",
        "abs",
        "absolute",
        "acos",
        "acosh",
        "add",
        "addbmm",
        "addcdiv",
        "addcmul",
        "addmm",
        "addmv",
        "alias",
        "all",
        "amax",
        "amin",
        "any",
        "arange",
        "argmax",
        "argmin",
        "asin",
        "asinh",
        "atan",
        "atan2",
        "atanh",
        "baddbmm",
        "bitwise_and",
        "bitwise_not",
        "bitwise_or",
        "bitwise_xor",
        "bmm",
        "broadcast_tensors",
        "cat",
        "ceil",
        "clamp",
        "clamp_max",
        "clamp_min",
        "clip",
        "clone",
        "contiguous",
        "copy",
        "copysign",
        "cos",
        "cosh",
        "cross",
        "cumprod",
        "cumsum",
        "deg2rad",
        "det",
        "detach",
        "diag",
        "diag_embed",
        "diagonal",
        "div",
        "dot",
        "elu",
        "eq",
        "erf",
        "erfc",
        "exp",
        "exp2",
        "expand",
        "expand_as",
        "expm1",
        "eye",
        "fill",
        "flatten",
        "flip",
        "floor",
        "floor_divide",
        "fmax",
        "fmin",
        "fmod",
        "frac",
        "full",
        "full_like",
        "gather",
        "ge",
        "gelu",
        "gt",
        "hardtanh",
        "heaviside",
        "hypot",
        "index",
        "index_put",
        "index_select",
        "inverse",
        "isfinite",
        "isinf",
        "isnan",
        "le",
        "leaky_relu",
        "lerp",
        "lift_fresh",
        "lift_fresh_copy",
        "linalg_cross",
        "linalg_det",
        "linalg_eigh",
        "linalg_inv",
        "linalg_inv_ex",
        "linalg_matrix_norm",
        "linalg_norm",
        "linalg_solve",
        "linalg_vector_norm",
        "linspace",
        "log",
        "log10",
        "log1p",
        "log2",
        "log_softmax",
        "logaddexp",
        "logical_and",
        "logical_not",
        "logical_or",
        "logical_xor",
        "logsumexp",
        "lt",
        "masked_fill",
        "matmul",
        "max",
        "maximum",
        "mean",
        "min",
        "minimum",
        "mm",
        "mul",
        "mv",
        "nan_to_num",
        "narrow",
        "ne",
        "neg",
        "norm",
        "ones",
        "ones_like",
        "outer",
        "permute",
        "pow",
        "prod",
        "rad2deg",
        "reciprocal",
        "relu",
        "remainder",
        "repeat",
        "reshape",
        "roll",
        "round",
        "rsqrt",
        "rsub",
        "scalar_tensor",
        "scatter",
        "select",
        "select_scatter",
        "sgn",
        "sigmoid",
        "sign",
        "silu",
        "sin",
        "sinh",
        "slice",
        "slice_scatter",
        "softmax",
        "softplus",
        "split",
        "split_with_sizes",
        "sqrt",
        "square",
        "squeeze",
        "stack",
        "std",
        "sub",
        "sum",
        "sym_numel",
        "size",
        "sym_size",
        "t",
        "tan",
        "tanh",
        "tile",
        "trace",
        "transpose",
        "tril",
        "triu",
        "true_divide",
        "trunc",
        "unbind",
        "unflatten",
        "unsqueeze",
        "var",
        "view",
        "view_as",
        "where",
        "xlogy",
        "zeros",
        "zero",
        "zeros_like",
    }
)

#: Factories of uninitialised memory, allowed with their results filled with zeros.
ZERO_FILLED = frozenset({"empty", "empty_like", "new_empty"})
ATEN_OPS_WITH_ZEROS = ATEN_OPS | {"new_zeros", "new_ones", "new_full"}

#: Python operators on sizes (symbolic integers of the batch dimension) and tuple items.
PYTHON_OPS = {
    f"operator.{name}": getattr(operator, name)
    for name in (
        "getitem", "add", "sub", "mul", "floordiv", "truediv", "mod", "neg", "pow",
        "eq", "ne", "lt", "le", "gt", "ge",
    )
}  # fmt: skip

#: Floating-point, integer and boolean dtypes a graph may name (floats run in the fit's dtype).
DTYPES = ("float16", "bfloat16", "float32", "float64", "int32", "int64", "bool")
FLOAT_DTYPES = frozenset({"float16", "bfloat16", "float32", "float64"})
LAYOUTS = ("strided",)
MEMORY_FORMATS = ("contiguous_format", "preserve_format")


def is_allowed(op: str) -> bool:
    """Whether ``op`` (``aten.<name>.<overload>`` or ``operator.<name>``) may appear."""
    if op in PYTHON_OPS:
        return True
    parts = op.split(".")
    if len(parts) != 3 or parts[0] != "aten":
        return False
    return parts[1] in ATEN_OPS_WITH_ZEROS or parts[1] in ZERO_FILLED
