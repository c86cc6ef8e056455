"""The MyVLM preparer: boxes, crops, masks and their check, licences, split by concept, both variants, errors.

Every test but the last runs on a small fake checkout written here (generated JPEGs in the
repository's layout and a boxes file of its own); none needs the real repository.
"""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest

from pin_match.cli.main import main
from pin_match.data.images import ImageFileError
from pin_match.data.mask_check import mask_problems
from pin_match.data.sources.lookalike_set import build
from pin_match.data.sources.myvlm import (
    BOXES_CSV,
    CONCEPT_CATEGORIES,
    MAX_SIDE,
    MYVLM_LICENCE,
    MYVLM_SOURCE,
    YOLLAVA_LICENCE,
    box_mask,
    crop_to_box,
    prepare_myvlm,
    read_boxes,
)
from pin_match.data.sources.photo_folder import LookalikeError, load_photos

CONCEPTS = ("billy_dog", "maeve_dog", "bo", "my_cat", "mam")  # three dogs (bo from Yo'LLaVA), two cats
OBJECT = (60, 80, 180, 260)  # x0, y0, x1, y1 of the ellipse's bounding box in every 400 x 300 photo
LICENCE_TEXT = "Copyright (c) 2024 Snap Inc. All rights reserved.\nnon-commercial, academic purposes only\n"


def _photo(colour: tuple[int, int, int], seed: int, fill: bool = False) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.clip(rng.normal(120, 8, (400, 300, 3)), 0, 255).astype(np.uint8)
    if fill:  # the object fills the photo: its mask must cross the border ring
        img[:] = colour
        return img
    x0, y0, x1, y1 = OBJECT
    cv2.ellipse(img, ((x0 + x1) // 2, (y0 + y1) // 2), ((x1 - x0) // 2, (y1 - y0) // 2), 0, 0, 360, colour, -1)
    return img


def fake_checkout(root):
    """Four photos per concept: 1-2 boxed, 3 left out by eye, 4 boxed but filled by the object (fails the check)."""
    rows = []
    for k, concept in enumerate(CONCEPTS):
        colour = (40 + 40 * k, 200 - 30 * k, 60 + 20 * k)
        folder = root / "dataset" / "data_concept_embedding" / concept
        folder.mkdir(parents=True)
        for j in range(1, 5):
            name = f"{j - 1}.png" if concept == "bo" else f"{concept}_{j}.jpg"
            assert cv2.imwrite(str(folder / name), _photo(colour, 10 * k + j, fill=j == 4)[..., ::-1])
            box = ("", "", "", "", "a second dog") if j == 3 else \
                (0, 0, 300, 400, "") if j == 4 else (OBJECT[0] - 10, OBJECT[1] - 10, OBJECT[2] + 10, OBJECT[3] + 10, "")
            rows.append([concept, name, *box])
        (folder / "captions.json").write_text("{}")
    (root / "LICENSE").write_text(LICENCE_TEXT)
    boxes = root.parent / "boxes.csv"
    with boxes.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["concept", "file", "x0", "y0", "x1", "y1", "dropped"])
        w.writerows(rows)
    return root, boxes


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    root = tmp_path_factory.mktemp("myvlm")
    repo, boxes = fake_checkout(root / "repo")
    return repo, boxes, prepare_myvlm(repo, root / "src", boxes=boxes)


def _rows(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_boxed_photos_are_cropped_masked_and_licensed(prepared):
    repo, _, src = prepared
    rows = _rows(src / "photos.csv")
    # photos 1 and 2 of each concept: 3 is left out by eye, 4 fails the mask check
    assert sorted(r["photo_id"] for r in rows) == sorted(
        f"myvlm_{c}_{j - 1 if c == 'bo' else j}" for c in CONCEPTS for j in (1, 2))
    for r in rows:
        concept = r["instance_id"].removeprefix("myvlm_")
        assert r["category"] == CONCEPT_CATEGORIES[concept]
        assert r["licence"] == (YOLLAVA_LICENCE if concept in ("bo", "mam") else MYVLM_LICENCE)
        assert r["source"] == MYVLM_SOURCE
        assert (repo / r["source_path"]).is_file() and r["use"] == ""
        photo = cv2.imread(str(src / r["file"]))[..., ::-1]
        k = CONCEPTS.index(concept)
        assert np.abs(photo[150, 105].astype(int) - (40 + 40 * k, 200 - 30 * k, 60 + 20 * k)).max() < 12  # RGB kept
        mask = cv2.imread(str(src / r["mask"]), cv2.IMREAD_GRAYSCALE) > 127
        # cropped to the box (140 x 200) grown by a quarter per side, clipped to the photo: 210 x 300
        assert photo.shape[:2] == mask.shape == (300, 210)
        truth = np.zeros(mask.shape, np.uint8)
        cv2.ellipse(truth, (105, 150), (60, 90), 0, 0, 360, 1, -1)
        iou = (mask & (truth > 0)).sum() / (mask | (truth > 0)).sum()
        assert iou > 0.9
    notice = (src / "NOTICE.md").read_text()
    assert "Copyright (c) 2024 Snap Inc." in notice and "commit unknown" in notice and "Yo'LLaVA" in notice
    assert "`billy_dog/billy_dog_3.jpg`: a second dog" in notice
    assert "`bo/3.png`: mask check: area" in notice  # filled by the object: area and border ring


def test_split_by_concept_keeps_each_category_whole(prepared):
    _, _, src = prepared
    split = {r["instance_id"]: r["split"] for r in _rows(src / "photos.csv")}
    dogs = {split[f"myvlm_{c}"] for c in ("billy_dog", "maeve_dog", "bo")}
    cats = {split[f"myvlm_{c}"] for c in ("my_cat", "mam")}
    assert dogs == {"train"} and cats == {"val"}  # three dogs first, the two cats alternate to val


@pytest.mark.parametrize("variant", ["shot", "pasted"])
def test_both_variants_build_from_the_source(prepared, tmp_path, variant):
    _, _, src = prepared
    fs = build(tmp_path / variant, src, variant=variant)
    split = {p.instance_id: p.split for p in load_photos(src)}
    assert sorted(fs.episodes.target_object_id) == sorted(f"myvlm_{c}" for c in CONCEPTS)
    roles = fs.visibility.merge(fs.frames[["frame_id", "episode_id"]], on="frame_id")
    for ep in fs.episodes.itertuples():
        mine = roles[roles.episode_id == ep.episode_id]
        assert {split[o] for o in mine.object_id} == {ep.split}
        assert (mine.role == "same_category").any()  # every target meets a same-category concept


def test_crop_shrinks_large_photos_and_keeps_the_box_on_the_object():
    img = np.zeros((3000, 4000, 3), np.uint8)
    img[1000:2000, 1500:2500] = (200, 40, 40)
    crop, box = crop_to_box(img, (1400, 900, 2600, 2100))
    assert max(crop.shape[:2]) == MAX_SIDE
    mask = box_mask(crop, box) > 0
    ys, xs = np.nonzero(mask)
    s = MAX_SIDE / 1800  # the crop: the box (1200 px) grown by 300 px per side
    assert abs(ys.min() - 400 * s) <= 3 and abs(xs.max() - 1400 * s) <= 3


def test_errors_name_the_problem_and_leave_nothing_behind(tmp_path):
    with pytest.raises(LookalikeError, match="not a MyVLM checkout"):
        prepare_myvlm(tmp_path, tmp_path / "src")
    repo, boxes = fake_checkout(tmp_path / "repo")
    (repo / "LICENSE").unlink()
    with pytest.raises(LookalikeError, match="LICENSE is missing"):
        prepare_myvlm(repo, tmp_path / "src", boxes=boxes)
    (repo / "LICENSE").write_text(LICENCE_TEXT)
    (repo / "dataset/data_concept_embedding/bo/1.png").unlink()
    with pytest.raises(LookalikeError, match=r"lacks photos boxed in .*\['bo/1.png'\]"):
        prepare_myvlm(repo, tmp_path / "src", boxes=boxes)
    (repo / "dataset/data_concept_embedding/bo/0.png").write_bytes(b"not a png")
    text = boxes.read_text().replace("bo,1.png", "bo,2.png")
    boxes.write_text(text)
    with pytest.raises(ImageFileError, match="corrupt or unreadable image .*bo/0.png"):
        prepare_myvlm(repo, tmp_path / "src", boxes=boxes)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["boxes.csv", "repo"]  # no source, no staging folder
    boxes.write_text(text.replace(",,,,,a second dog", ",1,2,3,4,a second dog", 1))
    with pytest.raises(LookalikeError, match="needs either four box coordinates or a reason"):
        read_boxes(boxes)
    boxes.write_text("concept,file,x0,y0,x1,y1,dropped\nunicorn,1.jpg,0,0,5,5,\n")
    with pytest.raises(LookalikeError, match="unknown concept 'unicorn'"):
        read_boxes(boxes)
    # the command line reaches the preparer (the shipped boxes name photos this fake checkout lacks)
    assert main(["data", "prepare", "myvlm", str(repo), "--out", str(tmp_path / "src")]) == 2


def test_the_shipped_boxes_cover_every_concept_with_look_alikes():
    photos = read_boxes(BOXES_CSV)
    boxed = {p.concept for p in photos if p.box}
    assert boxed == set(CONCEPT_CATEGORIES)
    per_category: dict[str, set[str]] = {}
    for c in boxed:
        per_category.setdefault(CONCEPT_CATEGORIES[c], set()).add(c)
    assert min(len(cs) for cs in per_category.values()) >= 2  # every concept has a real look-alike
    assert all(p.dropped for p in photos if not p.box)  # every photo left out by eye says why
    assert len({(p.concept, p.file) for p in photos}) == len(photos)


def test_the_hand_rule_is_left_out_for_objects_not_held():
    img = np.full((100, 100, 3), 60, np.uint8)
    img[30:70, 30:70] = (200, 140, 110)  # a tan dog's colour, inside the skin box
    mask = np.zeros((100, 100), np.uint8)
    mask[30:70, 30:70] = 1
    assert any("skin-coloured" in p for p in mask_problems(img, mask))
    assert mask_problems(img, mask, hand=False) == []
