"""A larger real look-alike source: packaged grocery products photographed in stores.

The Grocery Store Dataset (Klasson, Zhang and Kjellstroem, WACV 2019; MIT licence) holds smartphone
photos taken in Swedish grocery stores, most with the product held in a hand in front of the shelf,
and one iconic product image per class on a white background. Its packaged products are PIN's
look-alike problem at a larger scale than the CORe50 crops the toolkit ships: each fine class is one
product (one brand, flavour and fat content) and its coarse class holds other real products of the
same kind, shape and often brand (Juice: 10 products, Milk: 6, Yoghurt: 6, three classes of 2).

``prepare_grocery`` turns a checkout into the source folder ``pin_match.data.sources.lookalike_set.build``
reads (docs/lookalike-set.md):

- a product is an instance, its coarse class the category;
- its reference is its iconic image alone (``use=reference``), masked from the plain background.
  Store photos are not used as references: the border-seeded GrabCut mask (``object_mask``) often
  takes shelf or neighbouring packages and cuts the product, seen on a sample by eye;
- its frames are ``photos_per_product`` store photos, spread evenly over the dataset's
  train/val/test folders (neighbouring files are often shots of one moment); their masks come from
  ``object_mask`` and are rough, so the set measures detection, not localisation;
- splits by product (``split`` column): a category of 4 or more products is halved as
  ``instance_splits`` halves one, a smaller category goes whole to one split (so its products keep
  their look-alikes), the small ones alternating between train and val;
- empty rooms: the TUM office photos shipped with pin_match.

Fruit and vegetables are left out: their fine classes are varieties lying in piles (five apple
kinds, four peppers differing in colour alone), not single objects a user could own.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pin_match.data.compose import largest_piece
from pin_match.data.csv_rows import read_rows
from pin_match.data.images import read_image
from pin_match.data.sources import lookalike_set
from pin_match.data.sources.catalogue import SRC_REQUIRED, DataSource, register
from pin_match.data.sources.photo_folder import REFERENCE_USE, LookalikeError, category_splits
from pin_match.data.sources.prepare import Checkout, add_photo, notice, object_mask, open_checkout, write_source_folder

GROCERY_SOURCE = "github:marcusklasson/GroceryStoreDataset"
GROCERY_LICENCE = "MIT (Grocery Store Dataset, Klasson et al. 2019; Copyright (c) 2019 Marcus Klasson; file LICENSE)"
PRODUCT_GROUP = "Packages"  # the coarse-class folder of packaged products (the others: Fruit, Vegetables)
PHOTO_FOLDERS = ("train", "val", "test")  # the dataset's own photo splits, all used: the set splits by product
PHOTOS_PER_PRODUCT = 6
BACKGROUND_TOLERANCE = 24  # iconic images: a pixel is product when a channel differs this much from the border
CLASS_COLUMNS = ("Class Name (str)", "Coarse Class Name (str)", "Iconic Image Path (str)")
CLASSES_CSV = Path("dataset", "classes.csv")


@dataclass(frozen=True)
class Product:
    name: str  # the fine class, e.g. Bravo-Apple-Juice
    coarse: str  # its coarse class, e.g. Juice
    iconic: Path  # relative to the checkout
    photos: tuple[Path, ...]  # store photos, relative to the checkout, in folder order then name

    @property
    def instance_id(self) -> str:
        return f"grocery_{self.name.lower()}"

    @property
    def category(self) -> str:
        return self.coarse.lower()


def plain_background_mask(rgb: np.ndarray, tolerance: int = BACKGROUND_TOLERANCE) -> np.ndarray:
    """The product on an iconic image (uint8, 255 = product): what differs from the border's colour.

    The largest differing piece is kept and replaced by its convex hull: the packages are
    boxes and bottles, and their white parts touching the white background would otherwise be
    bitten out. All zero when nothing differs.
    """
    h, w = rgb.shape[:2]
    border = np.concatenate([rgb[0], rgb[-1], rgb[:, 0], rgb[:, -1]]).astype(np.int16)
    differs = (np.abs(rgb.astype(np.int16) - np.median(border, axis=0)).max(axis=2) > tolerance).astype(np.uint8)
    out = np.zeros((h, w), np.uint8)
    piece = largest_piece(differs)
    if piece.any():
        cv2.fillConvexPoly(out, cv2.convexHull(cv2.findNonZero(piece)), 255)
    return out


def read_products(repo: str | Path) -> list[Product]:
    """The packaged products of a checkout, with their iconic image and store photos."""
    repo = Path(repo)
    classes = repo / CLASSES_CSV
    if not classes.is_file():
        raise LookalikeError(f"{repo} is not a Grocery Store Dataset checkout: {classes} is missing")
    products = []
    for r in read_rows(classes, CLASS_COLUMNS, LookalikeError):
        iconic = Path("dataset", r["Iconic Image Path (str)"].lstrip("/"))
        folder = Path(*iconic.parent.parts[2:])  # e.g. Packages/Juice/Bravo-Apple-Juice
        if folder.parts[:1] != (PRODUCT_GROUP,):
            continue
        if not (repo / iconic).is_file():
            raise LookalikeError(f"iconic image of {r['Class Name (str)']} missing: {repo / iconic} "
                                 f"(named in {classes})")
        photos = tuple(p.relative_to(repo) for split in PHOTO_FOLDERS
                       for p in sorted((repo / "dataset" / split / folder).glob("*.jpg")))
        if not photos:
            raise LookalikeError(f"no store photo of {r['Class Name (str)']}: "
                                 f"{repo / 'dataset'}/{{{','.join(PHOTO_FOLDERS)}}}/{folder}/*.jpg is empty")
        products.append(Product(r["Class Name (str)"], r["Coarse Class Name (str)"], iconic, photos))
    if not products:
        raise LookalikeError(f"{classes} lists no {PRODUCT_GROUP} class: nothing to prepare")
    return products


def spread(photos: tuple[Path, ...], n: int) -> list[Path]:
    """``n`` photos evenly spaced over the list (all of them when there are fewer)."""
    if len(photos) <= n:
        return list(photos)
    return [photos[int(k)] for k in np.round(np.linspace(0, len(photos) - 1, n))]


def prepare_grocery(grocery_repo: str | Path, out: str | Path, *, photos_per_product: int = PHOTOS_PER_PRODUCT,
                    overwrite: bool = False) -> Path:
    """Write a look-alike source folder from a checkout of marcusklasson/GroceryStoreDataset."""
    if photos_per_product < 2:
        raise LookalikeError(f"photos_per_product must be at least 2, not {photos_per_product}")
    checkout = open_checkout(grocery_repo, GROCERY_SOURCE, CLASSES_CSV, "Grocery Store Dataset",
                             "the MIT notice must travel with the photos")
    products = read_products(checkout.root)
    split = category_splits(products)

    def write_photos(stage: Path) -> list[dict[str, str]]:
        rows = []
        for p in products:
            mask = plain_background_mask(read_image(checkout.root / p.iconic))
            if not mask.any():
                raise LookalikeError(f"iconic image {checkout.root / p.iconic} shows nothing on its plain background")
            row = _photo_row(checkout, stage, p, f"{p.instance_id}_iconic", p.iconic, mask)
            rows.append({**row, "split": split[p.instance_id], "use": REFERENCE_USE})
            for photo in spread(p.photos, photos_per_product):
                photo_id = f"grocery_{photo.parts[1]}_{photo.stem.lower()}"  # dataset/<folder>/.../<name>.jpg
                row = _photo_row(checkout, stage, p, photo_id, photo, object_mask(read_image(checkout.root / photo)))
                rows.append({**row, "split": split[p.instance_id], "use": ""})
        return rows

    return write_source_folder(out, write_photos, lambda rows, rooms: _notice(checkout, products, rows, rooms),
                               overwrite=overwrite)


def _photo_row(checkout: Checkout, stage: Path, product: Product, photo_id: str, path: Path,
               mask: np.ndarray) -> dict[str, str]:
    """Copy one photo and write its mask; its photos.csv row without split and use."""
    file, mask_file = add_photo(stage, photo_id, (checkout.root / path).read_bytes(), path.suffix.lower(), mask)
    return dict(photo_id=photo_id, instance_id=product.instance_id, category=product.category, file=file,
                mask=mask_file, source=checkout.source, source_path=path.as_posix(), licence=GROCERY_LICENCE)


def _notice(checkout: Checkout, products: list[Product], rows: list[dict], room_rows: list[dict]) -> str:
    n_iconic = sum(r["use"] == REFERENCE_USE for r in rows)
    photos = f"""`photos/` ({n_iconic} iconic product images and {len(rows) - n_iconic} store photos of
  {len(products)} packaged products) and the masks made from them (`masks/`: iconic images by
  `pin_match.data.sources.grocery.plain_background_mask`, store photos by
  `pin_match.data.sources.prepare.object_mask`): **Grocery Store Dataset**, M. Klasson, C. Zhang and
  H. Kjellstroem, "A Hierarchical Grocery Store Image Dataset with Visual and Semantic Labels",
  WACV 2019, https://github.com/marcusklasson/GroceryStoreDataset,
  commit {checkout.commit or 'unknown (not a git checkout)'}.
  Licence: **MIT**, copied below. Each photo's path in that repository is in `photos.csv`.
  Changes: file names, masks added."""
    return notice(photos, room_rows, "the Grocery Store Dataset", checkout.licence_text)


SOURCE = register(DataSource(
    name="grocery",
    summary="real look-alikes from a Grocery Store Dataset checkout: 31 packaged products in store photos, "
            "iconic images as references (prepare first; shot only: store-photo masks are rough)",
    licence="MIT (Grocery Store Dataset, Klasson et al. 2019)",
    variants=("shot",), make=lookalike_set.build, src=SRC_REQUIRED,
    prepare_inputs=("GROCERY_REPO",), make_source=prepare_grocery))
