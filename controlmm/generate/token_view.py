"""Text-view ensemble: the sentence-vector and the token-state masked transformers decode together.

With a trained ``token_transformer`` (:class:`~controlmm.models.config.TokenViewConfig`), each iteration of
text-only masked decoding (:func:`~controlmm.generate.generate`; not ``generate_controlled``, whose
motion control model extends the sentence-vector transformer) scores the tokens with both transformers
(classifier-free guidance each) and mixes their log-probabilities::

    log p = (1 - w) * log_softmax(cfg_logits_sentence) + w * log_softmax(cfg_logits_tokens)

The mix is returned as the iteration's logits (softmax of it is the normalised weighted geometric mean
of the two distributions), so top-k filtering, temperature, confidence scores and logits editing see one
table as before.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from controlmm.errors import ControlMMError
from controlmm.generate.masked_decoding import DecodeState, LogitsFn
from controlmm.models.model_dir import MotionModel


def token_view_logits_fn(
    model: MotionModel, texts: Sequence[str], cfg_scale: float, states: torch.Tensor | None = None
) -> LogitsFn | None:
    """A ``logits_fn`` for :func:`masked_decode` mixing both text views of ``texts``; None when the model
    has no token-state transformer (decoding then uses ``model.transformer`` alone). ``states``: the
    texts' (B, L, 384) token states when already encoded (:meth:`MotionModel.encode_text_views`)."""
    member = model.token_transformer
    if member is None:
        return None
    view = model.config.token_view
    if view is None:
        raise ControlMMError("the model has a token-state transformer but its model.json has no token_view")
    if states is None:
        states = model.encode_token_states(list(texts))  # (B, L, 384)
    weight = view.weight
    sentence = model.transformer

    def logits_fn(ids: torch.Tensor, state: DecodeState) -> torch.Tensor:
        a = torch.log_softmax(sentence.cfg_logits(ids, state.cond, state.padding_mask, cfg_scale), dim=-1)
        b = torch.log_softmax(member.cfg_logits(ids, states, state.padding_mask, cfg_scale), dim=-1)
        return (1.0 - weight) * a + weight * b

    return logits_fn
