"""PyReason's HuggingFaceLogicIntegratedClassifier (examples/image_classifier_ex.py): a Hugging Face
image classification model whose answer for one image becomes facts `label(identifier) : [l, u]`.

The contract is PyReason's: `classifier(inputs, t1=0, t2=0)` calls `model(**inputs).logits` (inputs is
what an image processor returns, a mapping such as {"pixel_values": ...}) and returns (logits,
probabilities, facts). The probabilities are the softmax over all the model's classes. Without
`limit_classes` the facts are one per class name, read from the first len(class_names) probabilities;
with it, the probabilities are kept only on the model's labels (`model.config.id2label`, the part before
the first comma, compared without case) that are among `class_names`, renormalised, and the facts are the
len(class_names) most probable labels, in that order, named as the model names them ("tiger shark";
PyReason's fact parser deletes the space: `tigershark(x)`). The bounds are classifier.py's.

transformers itself is not imported: the model arrives built (any object with that call surface and,
for `limit_classes`, a `config.id2label`), as in PyReason, whose module imports only torch. What needs
transformers is the script that builds the model; a script run by `python -m tracelab.pyreason` that
imports a package that is not installed gets a one-line error naming what to install (as_pyreason.py).
Where PyReason would fail inside torch or give NaN facts (several images at once, more class names than
the model has classes, no class name among the model's labels) this is a ValueError that says so."""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import torch

from .classifier import ModelInterfaceOptions, class_fact, fact_bounds
from .objects import Fact


class HuggingFaceLogicIntegratedClassifier(torch.nn.Module):
    """`classifier(inputs, t1, t2)` -> (logits [1, C], probabilities, facts); the facts hold at t1..t2."""

    def __init__(self, model: Any, class_names: Sequence[str], identifier: str = "hf_classifier",
                 interface_options: ModelInterfaceOptions | None = None, limit_classes: bool = False) -> None:
        super().__init__()
        self.model = model
        self.class_names = list(class_names)
        self.identifier = identifier
        self.interface_options = interface_options or ModelInterfaceOptions()
        self.limit_classes = limit_classes

    def forward(self, x: Mapping[str, Any], t1: int = 0, t2: int = 0) -> tuple[torch.Tensor, torch.Tensor, list[Fact]]:
        logits = self.model(**x).logits
        probabilities, labels = self._probabilities(logits)
        lower, upper = fact_bounds(probabilities, self.interface_options)
        facts = [class_fact(label, self.identifier, low, up, t1, t2)
                 for label, low, up in zip(labels, lower.tolist(), upper.tolist())]
        return logits, probabilities, facts

    def _probabilities(self, logits: torch.Tensor) -> tuple[torch.Tensor, list[str]]:
        """The probabilities the facts are read from, and their labels."""
        if logits.dim() != 2 or logits.size(0) != 1:
            raise ValueError(f"HuggingFaceLogicIntegratedClassifier classifies one image per call: the model "
                             f"gave logits of shape {tuple(logits.shape)}, expected [1, C]")
        if len(self.class_names) > logits.size(1):
            raise ValueError(f"HuggingFaceLogicIntegratedClassifier: {len(self.class_names)} class names for a "
                             f"model of {logits.size(1)} classes")
        probabilities = torch.softmax(logits, dim=1)[0]
        if not self.limit_classes:
            return probabilities, self.class_names
        return self._limited(probabilities)

    def _limited(self, probabilities: torch.Tensor) -> tuple[torch.Tensor, list[str]]:
        """PyReason's limit_classes: the probabilities on the allowed labels, renormalised, top k of them."""
        id2label = getattr(getattr(self.model, "config", None), "id2label", None)
        if not isinstance(id2label, Mapping):
            raise ValueError("HuggingFaceLogicIntegratedClassifier: limit_classes=True needs the model's "
                             "config.id2label (a Hugging Face model's config)")
        wanted = {name.lower() for name in self.class_names}
        allowed = [int(i) for i, label in id2label.items() if label.split(",")[0].strip().lower() in wanted]
        if not allowed:
            raise ValueError(f"HuggingFaceLogicIntegratedClassifier: none of the class names {self.class_names} "
                             "is a label of the model (config.id2label)")
        kept = torch.zeros_like(probabilities)
        kept[allowed] = probabilities[allowed]
        top, indices = (kept / kept.sum()).topk(len(self.class_names))
        labels = {int(i): label for i, label in id2label.items()}
        return top, [labels[i].split(",")[0] for i in indices.tolist()]
