"""The DiffusionPoser denoiser ``f(z_t, t, h) -> x0``.

Architecture (paper, Figure 2): a transformer *decoder*. The diffusion-step embedding
and the body-height embedding are two tokens that serve as the cross-attention memory
AND are prepended to the 61 frame tokens for self-attention. The output head reads
only the frame tokens and predicts the clean window x0 (normalised features).

The paper's model does not take the observation mask: inpainting (diffusion.inpaint) is
what makes one model serve every sensor subset. ``ModelConfig.mask_input`` adds the mask as
190 more input channels of each frame token (still one model for every subset, trained on
random masks); why it is the shipped choice is in docs/model.md ("Conditioning, masks and noise levels").
"""

from __future__ import annotations

import math
import warnings

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from inference.model.config import HEIGHT_MEAN, HEIGHT_STD, ModelConfig
from inference.model.diffusion import cosine_alpha_bar


def timestep_embedding(t: Tensor, dim: int, max_period: float = 10000.0) -> Tensor:
    """Sinusoidal embedding of integer diffusion levels, (B,) -> (B, dim)."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, dtype=torch.float32, device=t.device) / half)
    args = t.float()[:, None] * freqs[None]
    emb = torch.cat([torch.cos(args), torch.sin(args)], dim=-1)
    if dim % 2:
        emb = torch.cat([emb, torch.zeros_like(emb[:, :1])], dim=-1)
    return emb


class Denoiser(nn.Module):
    """Transformer-decoder denoiser; input and output (B, N, F) normalised features."""

    def __init__(self, config: ModelConfig | None = None) -> None:
        super().__init__()
        self.config = cfg = config or ModelConfig()
        d = cfg.d_model
        self.in_proj = nn.Linear(cfg.features * (2 if cfg.mask_input else 1), d)
        # learned positions for [step, height, frame_0 .. frame_{N-1}]
        self.pos = nn.Parameter(torch.zeros(1, cfg.window + 2, d))
        nn.init.normal_(self.pos, std=0.02)
        self.step_mlp = nn.Sequential(nn.Linear(d, d), nn.SiLU(), nn.Linear(d, d))
        self.height_mlp = nn.Sequential(nn.Linear(1, d), nn.SiLU(), nn.Linear(d, d))
        if cfg.readings:
            # zero at first: a model fine-tuned from one without readings starts as that model
            self.reading_emb = nn.Embedding(cfg.readings + 1, d)
            nn.init.zeros_(self.reading_emb.weight)
        if cfg.points:
            from inference.body.tracked import POINT_FEATURES

            self.points_proj = nn.Linear(POINT_FEATURES, d)
            nn.init.zeros_(self.points_proj.weight)
            nn.init.zeros_(self.points_proj.bias)
        layer = nn.TransformerDecoderLayer(
            d_model=d, nhead=cfg.heads, dim_feedforward=cfg.ff, dropout=cfg.dropout,
            activation="gelu", batch_first=True, norm_first=True,
        )
        self.decoder = nn.TransformerDecoder(layer, num_layers=cfg.layers)
        self.norm = nn.LayerNorm(d)
        self.out_proj = nn.Linear(d, cfg.features)
        if cfg.bypass:
            self.bypass = nn.Linear(cfg.features * (2 if cfg.mask_input else 1), cfg.features)
            nn.init.zeros_(self.bypass.weight)
            nn.init.zeros_(self.bypass.bias)
        if cfg.skip:
            ab = cosine_alpha_bar(cfg.T).float()
            self.register_buffer("skip_a", ab.sqrt(), persistent=False)
            self.register_buffer("skip_b", (1.0 - ab).clamp(min=0.0).sqrt(), persistent=False)

    def cond_tokens(self, t: Tensor, height: Tensor, reading: Tensor | None = None) -> Tensor:
        """(B, 2, d): the step token and the height token (with the reading's embedding)."""
        d = self.config.d_model
        dtype = self.pos.dtype
        step = self.step_mlp(timestep_embedding(t, d).to(dtype))
        h = ((height.to(dtype) - HEIGHT_MEAN) / HEIGHT_STD)[:, None]
        body = self.height_mlp(h)
        if self.config.readings:
            if reading is None:
                body = body + self.reading_emb.weight[self.config.reading].to(dtype)
            else:
                body = body + self.reading_emb(reading.long()).to(dtype)
        return torch.stack([step, body], dim=1)

    def forward(self, z: Tensor, t: Tensor, height: Tensor, mask: Tensor | None = None,
                reading: Tensor | None = None, points: Tensor | None = None) -> Tensor:
        """z (B, N, F) noised window, t (B,) int levels, height (B,) metres -> x0 (B, N, F).
        mask (B, N, F) bool, True = known: read only by ``mask_input`` models (None there
        means nothing is known: unconditional generation). reading (B,) int indices of
        READINGS for models with ``readings``; None = the model's own ``reading``.
        points (B, N, 16) or (1, N, 16): tracked points' position input for models with
        ``points`` (None: none tracked)."""
        n = z.shape[1]
        cond = self.cond_tokens(t, height, reading)
        inp = z
        if self.config.mask_input:
            m = torch.zeros_like(z) if mask is None else mask.to(z.dtype)
            inp = torch.cat([z, m], dim=-1)
        frames = self.in_proj(inp)
        if self.config.points and points is not None:
            frames = frames + self.points_proj(points.to(frames.dtype))
        tokens = torch.cat([cond, frames], dim=1) + self.pos[:, : n + 2]
        if self.training or torch.is_grad_enabled():
            h = self.decoder(tokens, cond)
        else:
            h = self._lean_decoder(tokens, cond)
        out = self.out_proj(self.norm(h[:, 2:]))
        if self.config.bypass:
            out = out + self.bypass(inp)
        if self.config.skip:
            a = self.skip_a[t].to(out.dtype)[:, None, None]
            b = self.skip_b[t].to(out.dtype)[:, None, None]
            out = a * z.to(out.dtype) + b * out
        return out

    def _lean_decoder(self, x: Tensor, mem: Tensor) -> Tensor:
        """The decoder stack in eval mode, written out with the layers' own weights.

        Same maths as ``nn.TransformerDecoder`` with norm_first layers (a test pins it),
        but about half the per-call time for live-size models on CPU: nn.MultiheadAttention
        spends more time in argument checks and reshapes than in arithmetic for a
        63-token window, and the live loop calls the model K times per 50 ms frame.
        """
        B, L, d = x.shape
        M = mem.shape[1]
        heads = self.config.heads
        hd = d // heads
        # the tokens as rows (B*L, d) between the attentions: a linear layer on a 2-D input is one
        # Gemm in the exported graph, on a 3-D one a Gemm between two Reshapes, each a node that
        # ONNX Runtime dispatches at a fixed cost (docs/latency.md, "int8 weights for the 21-frame file")
        x = x.reshape(B * L, d)
        mem = mem.reshape(B * M, d)
        for layer in self.decoder.layers:
            sa, ca = layer.self_attn, layer.multihead_attn
            # self-attention over [step, height, frames]
            y = F.layer_norm(x, (d,), layer.norm1.weight, layer.norm1.bias, layer.norm1.eps)
            # heads of q, k and v side by side (B, 3 heads, L, hd), cut in three: one Split, no Squeeze
            qkv = F.linear(y, sa.in_proj_weight, sa.in_proj_bias)
            q, k, v = qkv.view(B, L, 3 * heads, hd).transpose(1, 2).split(heads, 1)
            a = F.scaled_dot_product_attention(q, k, v)
            x = x + F.linear(a.transpose(1, 2).reshape(B * L, d), sa.out_proj.weight, sa.out_proj.bias)
            # cross-attention to the two memory tokens
            y = F.layer_norm(x, (d,), layer.norm2.weight, layer.norm2.bias, layer.norm2.eps)
            w, b = ca.in_proj_weight, ca.in_proj_bias
            q = F.linear(y, w[:d], b[:d]).view(B, L, heads, hd).transpose(1, 2)
            k, v = F.linear(mem, w[d:], b[d:]).view(B, M, 2 * heads, hd).transpose(1, 2).split(heads, 1)
            a = F.scaled_dot_product_attention(q, k, v)
            x = x + F.linear(a.transpose(1, 2).reshape(B * L, d), ca.out_proj.weight, ca.out_proj.bias)
            # feed-forward
            y = F.layer_norm(x, (d,), layer.norm3.weight, layer.norm3.bias, layer.norm3.eps)
            x = x + layer.linear2(F.gelu(layer.linear1(y)))
        return x.view(B, L, d)


def freeze_for_cpu(model: nn.Module, batch: int = 1, window: int | None = None) -> nn.Module:
    """TorchScript trace + freeze of a Denoiser for one fixed input shape (the live loop's
    (1, 61, 190)): same outputs, ~25-30% less time per call on CPU for live-size models
    (benchmarks/bench_model.py; int8 dynamic quantisation, bfloat16 and torch.compile
    bought nothing at these sizes). The result only accepts that shape; call it exactly
    like the model: ``f(z, t, height)``, or ``f(z, t, height, mask)`` for ``mask_input``."""
    model = model.eval()
    cfg = model.config
    n = window or cfg.window
    example = (torch.zeros(batch, n, cfg.features), torch.zeros(batch, dtype=torch.long), torch.full((batch,), 1.7))
    if cfg.mask_input:
        example = (*example, torch.ones(batch, n, cfg.features, dtype=torch.bool))
    with torch.inference_mode(False), torch.no_grad(), warnings.catch_warnings():
        # TorchScript is deprecated in favour of torch.compile, which here compiles for
        # ~40 s and then runs no faster than eager (docs/model.md, "Speed"); keep the lever that works
        warnings.simplefilter("ignore", DeprecationWarning)
        traced = torch.jit.trace(model, example, check_trace=False)
        frozen = torch.jit.freeze(traced)
    # TorchScript profiles the first call and optimises on the second; each is 5-20x a
    # later call. Made here, at load time, they do not stall the first live frames (the
    # live loop's first pose held the process for ~150 ms and its hub fell behind)
    with torch.inference_mode():
        for _ in range(2):
            frozen(*example)
    return frozen


def deepened_state_dict(state: dict[str, Tensor], model: nn.Module) -> dict[str, Tensor]:
    """``model``'s state with a shallower trained model of the same width in its first
    layers and every extra layer an exact identity (the outputs of its attention and
    feed-forward blocks zeroed, which pre-norm residual layers turn into a pass-through).

    The deeper model starts with the trained one's outputs and its new layers learn from
    there: more capacity for a fine-tune without paying for training from scratch.
    """
    own = model.state_dict()
    unknown = set(state) - set(own)
    if unknown:
        raise ValueError(f"the trained state has parameters this model lacks: {sorted(unknown)[:3]}")
    out = {}
    for k, v in own.items():
        if k in state:
            if state[k].shape != v.shape:
                raise ValueError(f"{k}: trained shape {tuple(state[k].shape)} != {tuple(v.shape)} (width differs)")
            out[k] = state[k].clone()
        elif k.startswith("decoder.layers.") and k.endswith(
                ("self_attn.out_proj.weight", "self_attn.out_proj.bias", "multihead_attn.out_proj.weight",
                 "multihead_attn.out_proj.bias", "linear2.weight", "linear2.bias")):
            out[k] = torch.zeros_like(v)
        elif k.startswith("decoder.layers."):
            out[k] = v.clone()
        else:
            raise ValueError(f"{k}: missing from the trained state")
    return out




