"""PyReason's HuggingFaceLogicIntegratedClassifier (examples/image_classifier_ex.py, issue 41): one image's
logits as facts, PyReason's call contract (`classifier(inputs, t1, t2)` calls `model(**inputs).logits`).
The model here is a small torch module with a Hugging Face model's call surface (keyword inputs, an
output with `.logits`, `config.id2label` as ImageNet's labels read); with transformers installed, also a
real ViT built from a config (no download). The expected facts are worked out by hand from the logits."""
from __future__ import annotations

import math
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace

import pytest

import tracelab.pyreason as pr

torch = pytest.importorskip("torch")
pytest.importorskip("pandas")
pytest.importorskip("networkx")

from tracelab.pyreason.hf_classifier import HuggingFaceLogicIntegratedClassifier  # noqa: E402 (after torch's skip)

# ImageNet's labels as a ViT's config names them ("name, synonyms"); "cock" is not an allowed label
ID2LABEL = {0: "goldfish, Carassius auratus", 1: "tiger shark, Galeocerdo cuvieri", 2: "hammerhead, hammerhead shark",
            3: "great white shark, white shark, man-eater", 4: "tench, Tinca tinca", 5: "cock"}
ALLOWED = ["goldfish", "tiger shark", "hammerhead", "great white shark", "tench"]  # the example's allowed_labels
EXAMPLE_OPTIONS = pr.ModelInterfaceOptions(threshold=0.5, set_lower_bound=True, set_upper_bound=False, snap_value=1.0)
# softmax(log p) = p: the model's probabilities over its 6 classes
SHARK = [0.02, 0.54, 0.09, 0.045, 0.005, 0.3]
FISH = [0.3, 0.01, 0.01, 0.01, 0.07, 0.6]


class TinyImageClassifier(torch.nn.Module):
    """A Hugging Face image classifier's call surface: `model(pixel_values=...)` -> an output whose
    `.logits` is [images, classes]; `config.id2label`. Its 'pixels' are the logits themselves."""

    def __init__(self) -> None:
        super().__init__()
        self.config = SimpleNamespace(id2label=dict(ID2LABEL))

    def forward(self, pixel_values: torch.Tensor) -> SimpleNamespace:
        return SimpleNamespace(logits=pixel_values.clone())


def image(probabilities: list[float]) -> dict[str, torch.Tensor]:
    return {"pixel_values": torch.log(torch.tensor([probabilities]))}


@pytest.fixture(autouse=True)
def fresh() -> Iterator[None]:
    pr.reset()
    pr.reset_rules()
    pr.reset_settings()
    yield
    pr.reset()
    pr.reset_rules()


def shown(facts: list[pr.Fact]) -> list[tuple[str, str]]:
    return [(str(f), f.name) for f in facts]


def test_limit_classes_renormalises_over_the_allowed_labels_and_names_the_top_ones_by_the_model() -> None:
    classify = HuggingFaceLogicIntegratedClassifier(TinyImageClassifier(), ALLOWED, identifier="shark_1",
                                                    interface_options=EXAMPLE_OPTIONS, limit_classes=True)
    logits, probabilities, facts = classify(image(SHARK), t1=2, t2=4)
    assert logits.shape == (1, 6)
    # cock (0.3) is dropped, the rest divided by 0.7, the 5 labels in falling order
    assert probabilities.tolist() == pytest.approx([0.54 / 0.7, 0.09 / 0.7, 0.045 / 0.7, 0.02 / 0.7, 0.005 / 0.7],
                                                   rel=1e-5)
    when = " | start: 2 -> end: 4"
    assert shown(facts) == [
        ("tigershark(shark_1) : [1.0,1.0]" + when, "shark_1-tiger shark-fact"),  # 0.77 > 0.5: snapped
        ("hammerhead(shark_1) : [0.0,1.0]" + when, "shark_1-hammerhead-fact"),
        ("greatwhiteshark(shark_1) : [0.0,1.0]" + when, "shark_1-great white shark-fact"),
        ("goldfish(shark_1) : [0.0,1.0]" + when, "shark_1-goldfish-fact"),
        ("tench(shark_1) : [0.0,1.0]" + when, "shark_1-tench-fact"),
    ]
    assert classify.class_names == ALLOWED  # PyReason keeps the filtered labels aside
    assert [(f.pred, f.component) for f in facts[:2]] == [("tigershark", "shark_1"), ("hammerhead", "shark_1")]


def test_without_limit_the_class_names_read_the_first_probabilities_of_the_whole_softmax() -> None:
    options = pr.ModelInterfaceOptions(threshold=0.5, set_lower_bound=True, set_upper_bound=True, snap_value=None)
    classify = HuggingFaceLogicIntegratedClassifier(TinyImageClassifier(), ALLOWED, identifier="shark_1",
                                                    interface_options=options)
    _, probabilities, facts = classify(image(SHARK))
    assert probabilities.tolist() == pytest.approx(SHARK, rel=1e-5)  # all 6 classes, cock's 0.3 kept
    assert [str(f).split(" |")[0] for f in facts] == [
        "goldfish(shark_1) : [0.0,1.0]", "tigershark(shark_1) : [0.54,0.54]", "hammerhead(shark_1) : [0.0,1.0]",
        "greatwhiteshark(shark_1) : [0.0,1.0]", "tench(shark_1) : [0.0,1.0]"]
    assert classify.identifier == "shark_1" and HuggingFaceLogicIntegratedClassifier(
        TinyImageClassifier(), ALLOWED).identifier == "hf_classifier"  # PyReason's default


@pytest.mark.filterwarnings("ignore:Rule is_.*has already been added")  # the example repeats rule names
def test_the_examples_rules_reason_on_the_facts_of_two_images() -> None:
    """examples/image_classifier_ex.py's program, its model replaced: a shark and a fish."""
    import networkx as nx
    pr.load_graph(nx.DiGraph())
    for text, name in [("is_fish(x) <-0 goldfish(x)", "is_fish_rule"), ("is_fish(x) <-0 tench(x)", "is_fish_rule"),
                       ("is_shark(x) <-0 tigershark(x)", "is_shark_rule"),
                       ("is_shark(x) <-0 hammerhead(x)", "is_shark_rule"),
                       ("is_shark(x) <-0 greatwhiteshark(x)", "is_shark_rule"),
                       ("is_scary(x) <-0 is_shark(x)", "is_scary_rule")]:
        pr.add_rule(pr.Rule(text, name))
    pr.add_rule(pr.Rule("likes_to_eat(y,x) <-0 is_shark(y), is_fish(x)", "likes_to_eat_rule", infer_edges=True))
    for identifier, probabilities in [("shark_1", SHARK), ("fish_1", FISH)]:
        classify = HuggingFaceLogicIntegratedClassifier(TinyImageClassifier(), ALLOWED, identifier=identifier,
                                                        interface_options=EXAMPLE_OPTIONS, limit_classes=True)
        for fact in classify(image(probabilities))[2]:
            pr.add_fact(fact)
    interpretation = pr.reason()
    nodes = interpretation.get_dict()[0]
    assert nodes["shark_1"]["is_scary"] == (1.0, 1.0)
    assert nodes["fish_1"]["is_fish"] == (1.0, 1.0)  # goldfish: 0.3 / 0.4 = 0.75 of the allowed labels
    assert "is_shark" not in nodes["fish_1"]
    assert interpretation.get_dict()[0][("shark_1", "fish_1")]["likes_to_eat"] == (1.0, 1.0)


@pytest.mark.parametrize(("pixels", "names", "limit", "says"), [
    (torch.zeros(2, 6), ALLOWED, False, "one image per call: the model gave logits of shape (2, 6)"),
    (torch.zeros(1, 4), ALLOWED, False, "5 class names for a model of 4 classes"),
    (torch.zeros(1, 6), ["shark"], True, "none of the class names ['shark'] is a label of the model"),
])
def test_what_pyreason_would_crash_on_or_answer_nan_is_a_value_error(pixels: torch.Tensor, names: list[str],
                                                                      limit: bool, says: str) -> None:
    classify = HuggingFaceLogicIntegratedClassifier(TinyImageClassifier(), names, limit_classes=limit)
    with pytest.raises(ValueError, match=says.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")):
        classify({"pixel_values": pixels})


def test_a_real_vit_built_from_a_config_classifies_through_it() -> None:
    transformers = pytest.importorskip("transformers")
    torch.manual_seed(0)
    config = transformers.ViTConfig(hidden_size=16, num_hidden_layers=1, num_attention_heads=2, intermediate_size=32,
                                    image_size=32, patch_size=16, num_labels=6, id2label=dict(ID2LABEL),
                                    label2id={v: k for k, v in ID2LABEL.items()})
    model = transformers.AutoModelForImageClassification.from_config(config).eval()
    inputs = {"pixel_values": torch.rand(1, 3, 32, 32)}
    classify = HuggingFaceLogicIntegratedClassifier(model, ALLOWED, identifier="img", limit_classes=True,
                                                    interface_options=pr.ModelInterfaceOptions(threshold=0.0,
                                                                                               snap_value=None))
    with torch.no_grad():
        logits, probabilities, facts = classify(inputs)
        expected = torch.softmax(model(**inputs).logits, dim=1)[0, :5]  # the allowed labels are classes 0..4
    expected = sorted(zip((expected / expected.sum()).tolist(), [ID2LABEL[i].split(",")[0] for i in range(5)]),
                      reverse=True)
    assert [f.name for f in facts] == [f"img-{label}-fact" for _, label in expected]
    assert [(f.literal.lower, f.literal.upper) for f in facts] == [
        (round(p, 3), round(p, 3)) for p, _ in expected]
    assert math.isclose(sum(probabilities.tolist()), 1.0, rel_tol=1e-5)


def run_script(tmp_path: Path, text: str) -> subprocess.CompletedProcess:
    script = tmp_path / "needs.py"
    script.write_text(text)
    return subprocess.run([sys.executable, "-m", "tracelab.pyreason", str(script)], capture_output=True, text=True,
                          timeout=300, check=False, cwd=tmp_path)


def test_a_script_importing_a_package_that_is_not_installed_is_one_line_naming_what_to_install(tmp_path: Path) -> None:
    r = run_script(tmp_path, "from pyreason.scripts.learning.classification.hf_classifier import "
                             "HuggingFaceLogicIntegratedClassifier\nimport tracelab_no_such_package.models\n")
    assert (r.returncode, r.stderr) == (1, f"tracelab: error: {tmp_path / 'needs.py'}:2: the script imports "
                                           "tracelab_no_such_package, which is not installed "
                                           "(pip install tracelab_no_such_package)\n")
    # a module missing inside an installed package is the script's own mistake: Python's traceback
    r = run_script(tmp_path, "import json.no_such_module\n")
    assert r.returncode == 1 and r.stderr.startswith("Traceback") and "json.no_such_module" in r.stderr


@pytest.mark.skipif(sys.modules.get("transformers") is not None or
                    __import__("importlib.util").util.find_spec("transformers") is not None,
                    reason="transformers is installed")
def test_the_image_classifier_examples_first_missing_import_is_transformers(tmp_path: Path) -> None:
    r = run_script(tmp_path, "from pathlib import Path\nimport torch\n"
                             "from transformers import AutoImageProcessor, AutoModelForImageClassification\n")
    assert r.stderr.endswith(":3: the script imports transformers, which is not installed (pip install transformers)\n")
