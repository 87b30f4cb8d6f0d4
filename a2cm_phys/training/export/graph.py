"""One actor as an ONNX graph, built with ``onnx.helper`` from its weights (no tracing).

The graph computes what :meth:`~a2cm_phys.algos.models.ActorCritic.actor_outputs` computes
for one agent: the observation, one-hot encoded per grid cell when the run's networks read
cells (:class:`~a2cm_phys.algos.encoding.OneHotCells`: ``round(x · (size − 1))`` clipped to
the arena, the same round-half-to-even as torch and numpy), then ``Gemm → Relu`` per hidden
layer and a last ``Gemm``: the logits, or a Gaussian's mean with its state-independent
``log_std`` broadcast to the batch.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from ...base.versions import __version__
from ...deploy.spec import FORMAT, INPUT, LOG_STD, LOGITS, MEAN, DeployError

if TYPE_CHECKING:
    import onnx

OPSET = 17
"""The ONNX opset of the exported graphs (onnxruntime ≥ 1.12 runs it)."""

IR_VERSION = 8
"""The ONNX IR version written (the one of opset 17), so that older runtimes load it."""

BATCH = "batch"
"""The name of the dynamic batch axis of every input and output."""


def onnx_module() -> ModuleType:
    """The ``onnx`` package, or a :class:`DeployError` naming the extra that installs it."""
    try:
        import onnx
    except ImportError:
        raise DeployError("exporting to ONNX needs onnx: pip install 'a2cm_phys[deploy]'") from None
    return onnx


@dataclass(frozen=True)
class ActorWeights:
    """One agent's actor as numpy float32: its dense layers ``(weight (out, in), bias
    (out,))`` from the input to the output, and a Gaussian actor's ``log_std``."""

    layers: Sequence[tuple[np.ndarray, np.ndarray]]
    log_std: np.ndarray | None = None

    @property
    def n_inputs(self) -> int:
        """Inputs of the first layer (the observation, or its one-hot cells)."""
        return int(self.layers[0][0].shape[1])

    @property
    def n_outputs(self) -> int:
        """Outputs of the last layer (logits, or the mean's dimensions)."""
        return int(self.layers[-1][0].shape[0])


def actor_model(
    weights: ActorWeights, obs_dim: int, cells: int | None, agent: str, doc: str = ""
) -> onnx.ModelProto:
    """The ONNX model of one actor: input :data:`~a2cm_phys.deploy.spec.INPUT` ``(batch,
    obs_dim)`` float32; outputs ``logits (batch, A)``, or ``mean`` and ``log_std (batch,
    2)`` when ``weights.log_std`` is given. ``cells``: the arena's size when the network
    reads one-hot cells, else ``None``."""
    lib = onnx_module()
    from onnx import TensorProto, helper, numpy_helper

    nodes, inits = [], []

    def const(name: str, value: np.ndarray) -> str:
        inits.append(numpy_helper.from_array(np.asarray(value), name))
        return name

    x = INPUT
    if cells is not None:
        x = _one_hot(nodes, const, x, cells)
    last = len(weights.layers) - 1
    head = LOGITS if weights.log_std is None else MEAN
    for k, (w, b) in enumerate(weights.layers):
        w_name = const(f"layer{k}.weight", w.astype(np.float32))
        b_name = const(f"layer{k}.bias", b.astype(np.float32))
        out = head if k == last else f"layer{k}"
        nodes.append(helper.make_node("Gemm", [x, w_name, b_name], [out], transB=1))
        if k < last:
            nodes.append(helper.make_node("Relu", [out], [f"relu{k}"]))
            out = f"relu{k}"
        x = out
    outputs = [(head, weights.n_outputs)]
    if weights.log_std is not None:
        std = const("log_std.value", weights.log_std.astype(np.float32).reshape(-1))
        nodes.append(helper.make_node("Shape", [MEAN], ["mean.shape"]))
        nodes.append(helper.make_node("Expand", [std, "mean.shape"], [LOG_STD]))
        outputs.append((LOG_STD, weights.n_outputs))
    graph = helper.make_graph(
        nodes,
        f"{agent}_actor",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, [BATCH, obs_dim])],
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, [BATCH, d]) for n, d in outputs],
        initializer=inits,
    )
    model = helper.make_model(
        graph,
        opset_imports=[helper.make_opsetid("", OPSET)],
        producer_name="a2cm_phys",
        producer_version=__version__,
        doc_string=doc,
    )
    model.ir_version = IR_VERSION
    helper.set_model_props(model, {"agent": agent, "format": FORMAT})
    lib.checker.check_model(model, full_check=True)
    return model


def _one_hot(nodes: list, const: Callable[[str, np.ndarray], str], x: str, cells: int) -> str:
    """Nodes that turn observations ``(batch, d)`` into one-hot cells ``(batch, d · cells)``
    (:class:`~a2cm_phys.algos.encoding.OneHotCells`); the name of their output."""
    from onnx import TensorProto, helper

    top = const("cells.top", np.float32(cells - 1))
    zero = const("cells.zero", np.float32(0))
    axis = const("cells.axis", np.array([-1], np.int64))
    values = const("cells.values", np.arange(cells, dtype=np.float32))
    shape = const("cells.shape", np.array([0, -1], np.int64))
    steps = [
        ("Mul", [x, top], "cells.scaled", {}),
        ("Round", ["cells.scaled"], "cells.rounded", {}),
        ("Clip", ["cells.rounded", zero, top], "cells.index", {}),
        ("Unsqueeze", ["cells.index", axis], "cells.column", {}),
        ("Equal", ["cells.column", values], "cells.hot", {}),
        ("Cast", ["cells.hot"], "cells.float", {"to": TensorProto.FLOAT}),
        ("Reshape", ["cells.float", shape], "cells", {}),
    ]
    for op, inputs, output, attrs in steps:
        nodes.append(helper.make_node(op, inputs, [output], **attrs))
    return "cells"
