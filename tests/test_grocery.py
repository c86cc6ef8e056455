"""The Grocery Store preparer: product selection, photo spread, split by product, labels, masks and errors.

Every test runs on a small fake checkout written here (tiny generated JPEGs and a classes.csv in the
dataset's layout); none needs the real repository.
"""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest

from pin_match.cli.main import main
from pin_match.data.images import ImageFileError
from pin_match.data.sources.grocery import (
    GROCERY_LICENCE,
    GROCERY_SOURCE,
    Product,
    plain_background_mask,
    prepare_grocery,
)
from pin_match.data.sources.lookalike_set import build, plan_episodes
from pin_match.data.sources.photo_folder import LookalikeError, category_splits, load_photos

HEADER = ["Class Name (str)", "Class ID (int)", "Coarse Class Name (str)", "Coarse Class ID (int)",
          "Iconic Image Path (str)", "Product Description Path (str)"]
# (group, coarse, fine, photos in train / val / test)
CLASSES = [("Fruit", "Apple", "Granny-Smith", (2, 0, 1)),
           ("Packages", "Juice", "Bravo-Apple-Juice", (4, 1, 3)),
           ("Packages", "Juice", "Bravo-Orange-Juice", (2, 0, 2)),
           ("Packages", "Juice", "Tropicana-Apple-Juice", (1, 1, 1)),
           ("Packages", "Juice", "Tropicana-Juice-Smooth", (2, 0, 1)),
           ("Packages", "Milk", "Arla-Standard-Milk", (2, 0, 2)),
           ("Packages", "Milk", "Garant-Standard-Milk", (1, 0, 2)),
           ("Packages", "Oat-Milk", "Oatly-Oat-Milk", (1, 0, 1))]
LICENCE_TEXT = "MIT License\n\nCopyright (c) 2019 Marcus Klasson\n"


def _write_jpg(path, image) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), image[..., ::-1])


def _store_photo(colour: tuple[int, int, int], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.clip(rng.normal(120, 10, (64, 64, 3)), 0, 255).astype(np.uint8)
    img[16:52, 22:42] = colour  # the package, held in the middle
    return img


def fake_checkout(root, classes=CLASSES, licence: bool = True):
    rows = []
    for k, (group, coarse, fine, counts) in enumerate(classes):
        folder = f"{group}/{coarse}/{fine}" if group == "Packages" or coarse != fine else f"{group}/{coarse}"
        iconic = f"/iconic-images-and-descriptions/{folder}/{fine}_Iconic.jpg"
        colour = (40 + 25 * k, 200 - 20 * k, 90)
        icon = np.full((60, 40, 3), 255, np.uint8)
        icon[8:52, 10:30] = colour
        _write_jpg(root / "dataset" / iconic.lstrip("/"), icon)
        for split, n in zip(("train", "val", "test"), counts):
            for j in range(1, n + 1):
                _write_jpg(root / "dataset" / split / folder / f"{fine}_{j:03d}.jpg", _store_photo(colour, 100 * k + j))
        rows.append([fine, k, coarse, k, iconic, iconic.replace("_Iconic.jpg", "_Description.txt")])
    with (root / "dataset" / "classes.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(HEADER)
        w.writerows(rows)
    if licence:
        (root / "LICENSE").write_text(LICENCE_TEXT)
    return root


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    root = tmp_path_factory.mktemp("grocery")
    repo = fake_checkout(root / "repo")
    return repo, prepare_grocery(repo, root / "src", photos_per_product=3)


def _rows(src):
    with open(src / "photos.csv", newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_products_their_iconic_reference_and_spread_store_photos(prepared):
    repo, src = prepared
    rows = _rows(src)
    by_instance: dict[str, list[dict]] = {}
    for r in rows:
        by_instance.setdefault(r["instance_id"], []).append(r)
    # packaged products only: the apple variety is left out
    assert sorted(by_instance) == sorted(f"grocery_{fine.lower()}" for group, _, fine, _ in CLASSES
                                         if group == "Packages")
    for (group, coarse, fine, counts) in CLASSES[1:]:
        own = by_instance[f"grocery_{fine.lower()}"]
        refs = [r for r in own if r["use"] == "reference"]
        assert [r["source_path"] for r in refs] == [
            f"dataset/iconic-images-and-descriptions/{group}/{coarse}/{fine}/{fine}_Iconic.jpg"]
        assert len(own) - 1 == min(3, sum(counts))
        assert {r["category"] for r in own} == {coarse.lower()}
    # 8 photos in folder order (train 001-004, val 001, test 001-003): 3 spread ones are the 1st, 5th and 8th
    bravo = [r["source_path"] for r in by_instance["grocery_bravo-apple-juice"] if not r["use"]]
    folder = "Packages/Juice/Bravo-Apple-Juice"
    assert sorted(bravo) == sorted([f"dataset/test/{folder}/Bravo-Apple-Juice_003.jpg",
                                    f"dataset/train/{folder}/Bravo-Apple-Juice_001.jpg",
                                    f"dataset/val/{folder}/Bravo-Apple-Juice_001.jpg"])
    for r in rows:  # every photo, mask and its provenance is there
        assert (src / r["file"]).is_file() and (src / r["mask"]).is_file()
        assert (repo / r["source_path"]).read_bytes() == (src / r["file"]).read_bytes()
        assert r["licence"] == GROCERY_LICENCE and r["source"] == GROCERY_SOURCE  # not a git checkout: no commit
    notice = (src / "NOTICE.md").read_text()
    assert "Copyright (c) 2019 Marcus Klasson" in notice and "commit unknown" in notice
    assert len(_rows_of(src / "rooms.csv")) == 10


def _rows_of(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_split_by_product_keeps_small_categories_whole(prepared):
    _, src = prepared
    split = {r["instance_id"]: r["split"] for r in _rows(src)}
    juice = [split[f"grocery_{fine.lower()}"] for _, coarse, fine, _ in CLASSES if coarse == "Juice"]
    assert sorted(juice) == ["train", "train", "val", "val"]  # 4 products: halved
    # smaller categories go whole, alternating from the larger: milk (2 products) train, oat milk (1) val
    assert split["grocery_arla-standard-milk"] == split["grocery_garant-standard-milk"] == "train"
    assert split["grocery_oatly-oat-milk"] == "val"


def test_small_categories_alternate_between_splits():
    products = [Product(f"{c}-{k}", c, None, ()) for c in ("Soy-Milk", "Soyghurt", "Sour-Cream") for k in range(2)]
    split = category_splits(products)
    per_category = {c: {split[p.instance_id] for p in products if p.coarse == c} for c in ("Soy-Milk", "Soyghurt",
                                                                                          "Sour-Cream")}
    assert all(len(s) == 1 for s in per_category.values())  # never split
    assert sorted(s.pop() for s in per_category.values()) == ["train", "train", "val"]


def test_plain_background_mask_is_the_package_with_white_parts_kept():
    img = np.full((60, 40, 3), 255, np.uint8)
    img[10:50, 8:32] = (30, 120, 200)  # the package: rows 10-49, columns 8-31
    img[10:20, 8:14] = 255  # its top-left corner is white, like the background it touches
    on = plain_background_mask(img) > 0
    assert on[10:50, 14:32].all() and on[20:50, 8:32].all()  # the coloured part
    assert on[19, 9] and not on[10, 8]  # the hull from (14, 10) to (8, 20) takes back the corner's lower half
    assert not (on[:10].any() or on[50:].any() or on[:, :8].any() or on[:, 32:].any())  # nothing off the package
    assert not plain_background_mask(np.full((20, 20, 3), 255, np.uint8)).any()


def test_the_prepared_source_builds_episodes_that_never_show_the_iconic_image(prepared, tmp_path):
    _, src = prepared
    photos = load_photos(src)
    plans = plan_episodes(photos, ["r1"])
    # juice: two products per split, each the other's look-alike; milk: both train; oat milk: no look-alike
    assert sorted(p.target for p in plans) == sorted(f"grocery_{fine.lower()}" for _, coarse, fine, _ in CLASSES
                                                    if coarse in ("Juice", "Milk"))
    for plan in plans:
        assert plan.reference_photos == (f"{plan.target}_iconic",)
        assert not [pid for _, pid in plan.frames if pid.endswith("_iconic")]
    fs = build(tmp_path / "shot", src)
    assert len(fs.episodes) == 6 and set(fs.episodes.split) == {"train", "val"}
    roles = fs.visibility.merge(fs.frames[["frame_id", "episode_id"]], on="frame_id")
    split = {p.instance_id: p.split for p in photos}
    for ep in fs.episodes.itertuples():
        mine = roles[roles.episode_id == ep.episode_id]
        assert (mine[mine.role == "target"].object_id == ep.target_object_id).all()
        assert {split[o] for o in mine.object_id} == {ep.split}  # a val episode shows val products only
    view = fs.target("grocery_bravo-apple-juice").views[0]
    # the iconic package (44 x 20 px, a JPEG) cut out by its mask
    assert abs(view.shape[0] - 44) <= 2 and abs(view.shape[1] - 20) <= 2 and view[..., 3].mean() > 0.95 * 255


def test_errors_name_the_problem_and_leave_nothing_behind(tmp_path):
    with pytest.raises(LookalikeError, match="classes.csv is missing"):
        prepare_grocery(tmp_path, tmp_path / "src")
    repo = fake_checkout(tmp_path / "repo", licence=False)
    with pytest.raises(LookalikeError, match="LICENSE is missing"):
        prepare_grocery(repo, tmp_path / "src")
    (repo / "LICENSE").write_text(LICENCE_TEXT)
    (repo / "dataset/train/Packages/Juice/Bravo-Orange-Juice/Bravo-Orange-Juice_001.jpg").write_bytes(b"not a jpeg")
    with pytest.raises(ImageFileError, match="corrupt or unreadable image .*Bravo-Orange-Juice_001.jpg"):
        prepare_grocery(repo, tmp_path / "src")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["repo"]  # no source folder, no staging folder
    for j in (1, 2):
        for split in ("train", "test"):
            (repo / f"dataset/{split}/Packages/Juice/Bravo-Orange-Juice/Bravo-Orange-Juice_{j:03d}.jpg").unlink()
    with pytest.raises(LookalikeError, match=r"no store photo of Bravo-Orange-Juice: .*Packages/Juice/Bravo-Orange"):
        prepare_grocery(repo, tmp_path / "src")
    _write_jpg(repo / "dataset/val/Packages/Juice/Bravo-Orange-Juice/Bravo-Orange-Juice_001.jpg",
               _store_photo((200, 100, 0), 0))
    (repo / "dataset/iconic-images-and-descriptions/Packages/Milk/Arla-Standard-Milk/"
            "Arla-Standard-Milk_Iconic.jpg").unlink()
    with pytest.raises(LookalikeError, match="iconic image of Arla-Standard-Milk missing"):
        prepare_grocery(repo, tmp_path / "src")
    (repo / "dataset/classes.csv").write_text("name,id\nx,1\n")
    with pytest.raises(LookalikeError, match="needs a header"):
        prepare_grocery(repo, tmp_path / "src")


def test_cli_prepares_then_builds_and_fails_with_one_line(tmp_path, capsys):
    repo = fake_checkout(tmp_path / "repo")
    assert main(["data", "build", "grocery", str(tmp_path / "shot")]) == 2
    assert "pin-match data prepare grocery GROCERY_REPO --out SRC" in capsys.readouterr().err
    assert main(["data", "prepare", "grocery", str(tmp_path / "nowhere"), "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert "classes.csv is missing" in err and len(err.strip().splitlines()) == 1
    assert main(["data", "prepare", "grocery", str(repo), "--out", str(tmp_path / "src")]) == 0
    assert main(["data", "prepare", "grocery", str(repo), "--out", str(tmp_path / "src")]) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(["data", "build", "grocery", str(tmp_path / "shot"), "--variant", "pasted", "--src",
                 str(tmp_path / "src")]) == 2
    assert "no variant 'pasted'" in capsys.readouterr().err
    assert main(["data", "build", "grocery", str(tmp_path / "shot"), "--src", str(tmp_path / "src")]) == 0
    assert (tmp_path / "shot").is_dir()
