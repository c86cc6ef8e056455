"""OWL-ViT matchers: the verdict and reference choice on hand-set numbers, and the real models on tiny checkpoints."""

from __future__ import annotations

import numpy as np
import pytest
from tiny_weights import save_tiny_owl

from conftest import striped_mug
from pin_match.contract.matcher import ConfigError, MatcherError, Modality, Target
from pin_match.contract.registry import create_matcher
from pin_match.matchers.owl import clip_tokenizer, closest_reference, owl_verdict


@pytest.fixture(scope="module")
def owl_dir(tmp_path_factory):
    return save_tiny_owl(tmp_path_factory.mktemp("owl"))


@pytest.fixture(scope="module")
def target():
    return striped_mug()


def frames():
    rng = np.random.default_rng(0)
    return [rng.integers(0, 256, (640, 360, 3), dtype=np.uint8), rng.integers(0, 256, (203, 331, 3), dtype=np.uint8)]


# ---------------------------------------------------------------------------- pure functions
def test_owl_verdict_scores_are_max_sigmoid_and_points_box_centres():
    logits = np.array([[0.0, -2.0], [3.0, 1.0], [-1.0, 2.0], [-4.0, -5.0]])  # 4 boxes x 2 queries
    boxes = np.array([[0.5, 0.5, 0.2, 0.2], [0.25, 0.75, 0.5, 0.1], [0.1, 0.2, 0.1, 0.1], [0.999, 0.0, 0.1, 0.1]])
    r = owl_verdict(logits, boxes, width=200, height=100, top_k=3)
    sig = lambda x: 1 / (1 + np.exp(-x))
    assert r.score == pytest.approx(sig(3.0))
    # best first: box 1 (sigmoid 3), box 2 (sigmoid 2), box 0 (sigmoid 0); box 3 is cut by top_k
    np.testing.assert_allclose(r.point_scores, [sig(3.0), sig(2.0), 0.5], rtol=1e-6)
    np.testing.assert_allclose(r.points, [[50, 75], [20, 20], [100, 50]], atol=1e-4)
    np.testing.assert_allclose(r.boxes[0], [0, 70, 100, 80], atol=1e-4)
    np.testing.assert_array_equal(r.box_scores, r.point_scores)
    # no threshold inside: the weakest kept box is returned too, and points_at applies sigma
    assert len(r.points_at(0.6)) == 2 and len(r.points_at(0.99)) == 0


def test_owl_verdict_clips_centres_into_the_crop():
    r = owl_verdict(np.array([[1.0]]), np.array([[1.0, 1.0, 0.5, 0.5]]), width=64, height=32, top_k=5)
    assert r.points[0, 0] <= 63 and r.points[0, 1] <= 31
    np.testing.assert_allclose(r.boxes[0], [48, 24, 64, 32])


def test_closest_reference_uses_cosine_not_dot_product():
    refs = np.array([[10.0, 0.0], [0.1, 0.1], [0.0, -1.0]])
    obs = np.array([[1.0, 1.0], [5.0, 0.5], [0.2, -3.0]])
    # obs 0 is parallel to ref 1 although ref 0 has the larger dot product
    np.testing.assert_array_equal(closest_reference(obs, refs), [1, 0, 2])


def test_tokenizer_is_open_clips_with_owl_padding():
    import open_clip

    tok = clip_tokenizer(16)
    text = "a photo of a red mug with white stripes on the handle and a small logo on its side"
    ids = tok([text, "hat"], padding="max_length", truncation=True, return_tensors="np")["input_ids"]
    np.testing.assert_array_equal(ids, open_clip.get_tokenizer("ViT-B-32")([text, "hat"], context_length=16).numpy())
    assert ids.shape == (2, 16) and ids[1, 3] == 0


# ---------------------------------------------------------------------------- configuration
def test_query_is_checked_and_category_query_changes_modality():
    with pytest.raises(ConfigError, match="query"):
        create_matcher("owl", query="label")
    with pytest.raises(ConfigError, match="prompt='templates'"):
        create_matcher("owl", prompt="templates")
    assert create_matcher("owl").cfg.prompt == "description"
    assert create_matcher("owl").modality is Modality.TEXTUAL
    assert create_matcher("owl", query="category").modality is Modality.CATEGORY
    with pytest.raises(ConfigError, match="top_k"):
        create_matcher("owl-image", top_k=0)


def test_construction_loads_nothing_and_offline_error_names_hub_id_and_override(target):
    m = create_matcher("owl")  # no weights anywhere, offline: construction still succeeds
    with pytest.raises(OSError, match=r"google/owlvit-base-patch32.*weights="):
        m.prepare(target)


# ---------------------------------------------------------------------------- tiny real models
@pytest.mark.parametrize("name,options", [("owl", {}), ("owl", {"prompt": "imagenet-80"}), ("owl-image", {})])
def test_tiny_checkpoint_gives_valid_deterministic_results(owl_dir, target, name, options):
    m = create_matcher(name, weights=owl_dir, top_k=7, **options)
    m.prepare(target)
    for frame in frames():
        r = m.match(frame)
        assert 0.0 <= r.score <= 1.0
        assert len(r.crop_scores) == 2  # PIN's two square crops
        assert len(r.points) == 2 * 7 and r.score == pytest.approx(float(r.box_scores.max()))
        h, w = frame.shape[:2]
        assert (r.boxes[:, [0, 2]] <= w).all() and (r.boxes[:, [1, 3]] <= h).all()
        again = m.match(frame)
        assert again.score == r.score
        np.testing.assert_array_equal(again.points, r.points)


def test_text_queries_are_unit_vectors_one_per_description(owl_dir, target):
    m = create_matcher("owl", weights=owl_dir)
    m.prepare(target)
    queries = m._queries.numpy()
    assert queries.shape[0] == 3
    np.testing.assert_allclose(np.linalg.norm(queries, axis=1), 1.0, rtol=1e-5)


def test_category_query_reads_the_label_and_needs_it(owl_dir, target):
    m = create_matcher("owl", weights=owl_dir, query="category")
    m.prepare(target)
    assert m._queries.shape[0] == 1
    with pytest.raises(MatcherError, match="empty category"):
        m.prepare(Target(target.object_id, "", target.views, target.descriptions))


# ---------------------------------------------------------------------------- against CLIP on Wheels' ClipOwl
def clip_owl_score(model, image: np.ndarray, sentence: str) -> float:
    """CoW's ``ClipOwl.forward`` for one sentence, re-implemented: open_clip's tokenizer cut to OWL's 16 tokens
    (padding id 0), the processor's resize and normalisation, the full detection forward, then the best box's
    sigmoid (its ``post_process``: max over queries, then sigmoid)."""
    import open_clip
    import torch
    from transformers import OwlViTImageProcessor

    ids = open_clip.get_tokenizer("ViT-B-32")([sentence], context_length=16)
    side = model.config.vision_config.image_size
    pixels = OwlViTImageProcessor(size={"height": side, "width": side})(images=[image], return_tensors="pt")
    with torch.no_grad():
        out = model(input_ids=ids, attention_mask=(ids != 0).long(), pixel_values=pixels["pixel_values"])
    return float(torch.sigmoid(out.logits[0].max(dim=-1).values).max())


def long_target(target):
    long = "a small red ceramic coffee mug with thin yellow stripes and a chipped white handle on the left side"
    return Target(target.object_id + "_long", target.category, target.views, (long, "a striped cup", "a red mug"))


@pytest.mark.parametrize("prompt,sentence", [("description", "{}"), ("a-photo-of", "a photo of a {}.")])
def test_text_scores_equal_clip_owl_forward(owl_dir, target, prompt, sentence):
    from transformers import OwlViTForObjectDetection

    model = OwlViTForObjectDetection.from_pretrained(owl_dir).eval()
    m = create_matcher("owl", weights=owl_dir, crops="whole", prompt=prompt)
    image = np.random.default_rng(3).integers(0, 256, (360, 360, 3), dtype=np.uint8)
    for t in (target, long_target(target)):
        with pytest.warns() if t is not target else _no_warning():
            m.prepare(t)
        expected = max(clip_owl_score(model, image, sentence.format(d)) for d in t.descriptions)
        assert m.match(image).score == pytest.approx(expected, abs=1e-6)


def _no_warning():
    import contextlib
    import warnings

    @contextlib.contextmanager
    def ctx():
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            yield

    return ctx()


def test_truncated_prompts_warn_once_per_target(owl_dir, target):
    from pin_match.matchers.owl import TruncationWarning

    m = create_matcher("owl", weights=owl_dir)
    with pytest.warns(TruncationWarning, match=r"target mug_x_long: 1 prompt\(s\) longer than OWL-ViT's 16 tokens"):
        m.prepare(long_target(target))
    with _no_warning():
        m.prepare(long_target(target))  # the same target again: already reported
        m.prepare(target)               # short descriptions: nothing to report
    m80 = create_matcher("owl", weights=owl_dir, prompt="imagenet-80")
    with pytest.warns(TruncationWarning, match=r"mug_x_long: 8\d prompt\(s\)"):  # every template cuts it
        m80.prepare(long_target(target))
