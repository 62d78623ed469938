"""The live denoiser call through ONNX Runtime instead of torch, where it is faster.

The live loop calls the model a few times per 50 ms frame on one fixed input shape, from
one CPU thread. At that size torch spends a good part of each call in dispatch between
small kernels; ONNX Runtime runs the same graph (exported once per model and shape, in
memory, mirror averaging included) with fused kernels. ``imucap bench`` times both in one
run (``onnx_p50_ms`` next to ``p50_ms``); docs/latency.md has the figures.

Where it is used: only where a caller asks for it (``Poser(runtime="auto")``: the live
sessions), so offline evaluation keeps torch's results bit for bit (ONNX Runtime agrees
with torch to ~1e-6, not exactly). ``auto`` takes ONNX Runtime when it is installed and
torch otherwise; ``IMUCAP_RUNTIME=torch|onnx`` overrides ``auto`` (e.g. to compare).
onnxruntime is optional (``pip install imucap[onnx]``): without it everything runs on torch.
"""

from __future__ import annotations

import io
import os
import warnings
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

RUNTIMES = ("torch", "onnx", "auto")
OPSET = 17

# ONNX Runtime's Linux build carries Microsoft's 1DS telemetry, which resolves its event
# host from a thread of its own some seconds after the first session (two DNS queries per
# live run, seen with strace). imucap sends nothing off the machine that its user did not
# ask for. Read once, when onnxruntime is first imported: every import of it is below.
os.environ.setdefault("ORT_DISABLE_TELEMETRY", "1")


def onnxruntime_available() -> bool:
    """Whether the ONNX path can run here: torch exports the model with ``onnx`` and
    ``onnxruntime`` runs it; one without the other is no use."""
    try:
        import onnx  # noqa: F401
        import onnxruntime  # noqa: F401
    except ImportError:
        return False
    return True


def resolve_runtime(requested: str = "auto") -> str:
    """"torch" or "onnx" for a request ("auto" follows IMUCAP_RUNTIME, else takes ONNX
    Runtime when it is installed). An explicit "onnx" without onnxruntime is an error."""
    if requested not in RUNTIMES:
        raise ValueError(f"unknown runtime {requested!r}; choose from {', '.join(RUNTIMES)}")
    if requested == "auto":
        env = os.environ.get("IMUCAP_RUNTIME", "auto")
        if env not in RUNTIMES:
            raise ValueError(f"IMUCAP_RUNTIME={env!r}: choose from {', '.join(RUNTIMES)}")
        requested = env if env != "auto" else ("onnx" if onnxruntime_available() else "torch")
    if requested == "onnx" and not onnxruntime_available():
        raise ImportError("the ONNX runtime was asked for but onnx or onnxruntime is not installed "
                          "(pip install '.[onnx]')")
    return requested


class OnnxNet:
    """``module`` (a denoiser, or a wrapper called like one: ``(z, t, height[, mask])``)
    exported for one input shape and run by ONNX Runtime; called like the module, returns
    a torch tensor. ``threads``: ONNX Runtime's intra-op threads (default torch's own
    setting, which the live loop keeps at 1). ``quantize``: the exported graph's weights
    (MatMul, Gemm) quantized to int8 with ONNX Runtime's dynamic quantizer (activations
    quantized per call); ``imucap bench`` measures it beside the float graph and
    docs/latency.md says why it is not the default."""

    def __init__(self, module: nn.Module, batch: int, window: int, features: int, mask_input: bool,
                 threads: int | None = None, quantize: bool = False) -> None:
        import onnxruntime as ort

        self.config = getattr(module, "config", None)
        self.shape = (batch, window, features)
        self.mask_input = mask_input
        example: tuple[Tensor, ...] = (torch.zeros(self.shape), torch.zeros(batch, dtype=torch.long),
                                       torch.full((batch,), 1.7))
        names = ["z", "t", "height"]
        if mask_input:
            example = (*example, torch.ones(self.shape, dtype=torch.bool))
            names.append("mask")
        self.names = names
        buf = io.BytesIO()
        was_training = module.training
        module.eval()
        # eval mode without autograd: the denoiser's lean decoder is what gets exported
        with torch.inference_mode(False), torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            torch.onnx.export(module, example, buf, dynamo=False, opset_version=OPSET, input_names=names,
                              output_names=["x0"])
        module.train(was_training)
        graph = buf.getvalue()
        if quantize:
            graph = quantize_dynamic_int8(graph)
        self.threads = max(1, threads if threads is not None else torch.get_num_threads())
        self.quantized = quantize
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = self.threads
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self.session = ort.InferenceSession(graph, opts, providers=["CPUExecutionProvider"])

    def run_np(self, z: np.ndarray, t: np.ndarray, height: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """The call on numpy arrays (float32 z and height, int64 t, bool mask), answered in
        numpy: what ``diffusion.inpaint``'s live loop uses, with no tensor made per call."""
        feeds: dict[str, Any] = {"z": z, "t": t, "height": height}
        if self.mask_input:
            feeds["mask"] = np.zeros(self.shape, dtype=bool) if mask is None else mask
        return self.session.run(None, feeds)[0]

    def __call__(self, z: Tensor, t: Tensor, height: Tensor, mask: Tensor | None = None) -> Tensor:
        return _call_on_tensors(self.run_np, z, t, height, mask)


def _call_on_tensors(run_np, z: Tensor, t: Tensor, height: Tensor, mask: Tensor | None) -> Tensor:
    """A numpy network's ``run_np`` called like the torch module: tensors in, a tensor out."""
    def arr(x: Tensor, dtype) -> np.ndarray:
        return np.ascontiguousarray(x.detach().numpy(), dtype=dtype)

    return torch.from_numpy(run_np(arr(z, np.float32), arr(t, np.int64), arr(height, np.float32),
                                   None if mask is None else arr(mask, bool)))


class PerWindowNet:
    """A one-window session called once per window of a batch. An int8 graph quantizes each
    activation with one scale over its whole input tensor (``DynamicQuantizeLinear``), so a
    window's answer would depend on the other windows in its batch; called one by one, an
    offline run's answers are exactly the live loop's (which calls one window a frame)."""

    def __init__(self, one: OnnxNet) -> None:
        self.one = one
        self.config = one.config
        self.mask_input = one.mask_input
        self.quantized = one.quantized
        self.threads = one.threads

    def run_np(self, z: np.ndarray, t: np.ndarray, height: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        return np.concatenate([self.one.run_np(z[i:i + 1], t[i:i + 1], height[i:i + 1],
                                               None if mask is None else mask[i:i + 1]) for i in range(len(z))])

    def __call__(self, z: Tensor, t: Tensor, height: Tensor, mask: Tensor | None = None) -> Tensor:
        return _call_on_tensors(self.run_np, z, t, height, mask)


def quantize_dynamic_int8(graph: bytes) -> bytes:
    """An ONNX graph with its MatMul / Gemm weights in int8 (ONNX Runtime's dynamic
    quantizer: per-tensor weight scales, activations quantized on the fly)."""
    import tempfile
    from pathlib import Path

    import onnx
    from onnxruntime.quantization import QuantType, quantize_dynamic
    from onnxruntime.quantization.shape_inference import quant_pre_process

    with tempfile.TemporaryDirectory() as tmp:
        src, pre, dst = Path(tmp, "f32.onnx"), Path(tmp, "pre.onnx"), Path(tmp, "int8.onnx")
        src.write_bytes(graph)
        try:
            quant_pre_process(str(src), str(pre), skip_symbolic_shape=True)
        except Exception:  # noqa: BLE001 - the pre-pass only helps; quantize the graph as exported
            pre = src
        quantize_dynamic(str(pre), str(dst), op_types_to_quantize=["MatMul", "Gemm"], weight_type=QuantType.QInt8)
        return onnx.load(str(dst)).SerializeToString()


def onnx_net(module: nn.Module, batch: int, window: int, features: int, mask_input: bool,
             quantize: bool = False) -> OnnxNet | PerWindowNet | None:
    """``OnnxNet`` of ``module``, or None (with a warning) when the export or the session
    fails: the caller then runs torch, so a model ONNX cannot take still runs. ``quantize``:
    the int8 graph, one window a call (``PerWindowNet`` for a batch of them)."""
    try:
        if quantize:
            one = OnnxNet(module, 1, window, features, mask_input, quantize=True)
            return one if batch == 1 else PerWindowNet(one)
        return OnnxNet(module, batch, window, features, mask_input)
    except Exception as exc:  # noqa: BLE001 - any failure falls back to torch, said once
        warnings.warn(f"ONNX Runtime unavailable for this model ({type(exc).__name__}: {exc}); running torch",
                      stacklevel=2)
        return None


__all__ = ["RUNTIMES", "onnxruntime_available", "resolve_runtime", "OnnxNet", "PerWindowNet", "onnx_net",
           "quantize_dynamic_int8"]
