"""Object instances: the 18 PIN categories, per-instance attributes and the descriptions written from them.

An instance is fully described by its ``ObjectSpec`` (a few names and numbers), so worker
processes rebuild its mesh and texture from the spec instead of receiving arrays, and the
descriptions name exactly the attributes that were painted. Siblings of one category never
share the same attribute key, so their descriptions always tell them apart.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from pin_match.data.compose import stable_seed
from pin_match.data.synth import prints
from pin_match.data.synth.textures import WORDS
from pin_match.errors import PinMatchError


class SynthError(PinMatchError, ValueError):
    """Generator settings that cannot make a frame-set (too few episodes, objects or frames)."""

CATEGORIES = ("backpack", "bag", "ball", "book", "camera", "cellphone", "eyeglasses", "hat", "headphones", "keys",
              "laptop", "mug", "shoes", "teddy bear", "toy", "visor", "wallet", "watch")

BRIGHT = ("red", "orange", "yellow", "lime green", "green", "teal", "light blue", "blue", "navy", "purple", "pink",
          "magenta", "white", "black", "grey", "brown", "beige", "maroon", "mint", "lavender", "coral", "olive")
NEUTRAL = ("black", "dark grey", "grey", "navy", "brown", "dark brown", "tan", "beige", "white", "maroon", "olive")
METAL = ("silver", "dark grey", "black", "gold", "rose gold", "white")


@dataclass(frozen=True)
class Category:
    """How much instances of a category vary, and which words describe them.

    ``spread`` (0..1) scales proportion jitter, size and the share of families carrying a
    pattern: PIN's eyeglasses are near-identical (DINOv2 intra-category similarity 0.85), its
    toys have little in common (0.14).
    """

    name: str
    variants: tuple[str, ...]
    colours: tuple[str, ...]
    colours2: tuple[str, ...]
    trim: str  # how colour2 is said: "with {c2} straps"
    patterns: tuple[str, ...] = ("plain",)
    spread: float = 0.5
    prints: bool = True  # whether the shape has a place where a photo is printed
    words: bool = True


CATEGORY_SPECS: dict[str, Category] = {c.name: c for c in (
    Category("backpack", ("backpack", "hiking backpack", "small backpack"), BRIGHT, NEUTRAL + ("red", "yellow"),
             "with {c2} straps and pocket", ("plain", "striped", "camouflage", "checked", "polka-dot"), 0.6),
    Category("bag", ("tote bag", "handbag", "duffel bag", "messenger bag"), BRIGHT + NEUTRAL, NEUTRAL + ("gold",),
             "with {c2} handles", ("plain", "striped", "checked", "floral", "plaid", "polka-dot"), 0.9),
    Category("ball", ("beach ball", "soccer ball", "rubber ball", "tennis ball"), BRIGHT, ("white", "black", "yellow",
             "red", "blue"), "with {c2} markings", ("striped", "checked", "plain", "polka-dot"), 0.6),
    Category("book", ("hardcover book", "paperback book", "notebook"), BRIGHT + NEUTRAL, ("white", "cream"),
             "with {c2} pages", ("plain", "striped", "plaid"), 0.5),
    Category("camera", ("DSLR camera", "compact camera", "instant camera"), ("black", "silver", "dark grey", "white",
             "mint", "pink", "light blue", "tan"), ("black", "silver", "brown", "red"), "with a {c2} lens ring",
             ("plain",), 0.4),
    Category("cellphone", ("smartphone", "phone"), METAL + ("blue", "red", "green", "purple", "pink"),
             ("black", "silver", "white"), "with a {c2} camera bump", ("plain",), 0.3),
    Category("eyeglasses", ("round glasses", "rectangular glasses"), ("black", "dark brown", "tortoiseshell", "gold",
             "silver"), ("clear", "grey", "brown", "blue"), "with {c2} lenses", ("plain",), 0.05, False, False),
    Category("hat", ("baseball cap", "bucket hat", "beanie", "fedora"), BRIGHT + NEUTRAL, NEUTRAL + ("red",),
             "with a {c2} band", ("plain", "striped", "checked", "camouflage", "plaid"), 0.7),
    Category("headphones", ("over-ear headphones", "on-ear headphones", "gaming headset"), ("black", "white", "silver",
             "navy", "red", "pink", "grey", "rose gold", "blue"), ("black", "grey", "white", "brown"),
             "with {c2} ear cushions", ("plain",), 0.35),
    Category("keys", ("keys", "set of keys"), ("silver", "gold", "dark grey"), ("red", "blue", "black", "green",
             "yellow", "pink"), "on a ring with a {c2} tag", ("plain",), 0.1, False),
    Category("laptop", ("laptop", "notebook computer"), ("silver", "dark grey", "black", "white", "rose gold", "gold"),
             ("black", "dark grey", "white"), "with a {c2} keyboard", ("plain",), 0.25),
    Category("mug", ("mug", "tall mug", "travel mug"), BRIGHT, ("white", "black", "red", "blue", "yellow", "grey"),
             "with a {c2} handle", ("plain", "striped", "polka-dot", "checked", "zigzag"), 0.6),
    Category("shoes", ("sneakers", "boots", "running shoes"), BRIGHT + NEUTRAL, ("white", "black", "grey", "brown"),
             "with {c2} soles", ("plain", "striped", "checked"), 0.5),
    Category("teddy bear", ("teddy bear", "small teddy bear", "big teddy bear"), ("brown", "tan", "white", "cream",
             "pink", "grey", "light blue", "dark brown", "beige", "lavender"), ("red", "blue", "green", "yellow",
             "pink", "purple"), "wearing a {c2} bow", ("plain",), 0.8, True, False),
    Category("toy", ("toy car", "toy robot", "rubber duck", "toy rocket", "stacking rings toy"), BRIGHT,
             BRIGHT, "with {c2} parts", ("plain", "striped", "checked", "polka-dot"), 1.0),
    Category("visor", ("sun visor", "sports visor"), ("white", "black", "navy", "pink", "red", "light blue", "grey"),
             ("white", "black", "grey"), "with a {c2} headband", ("plain",), 0.1),
    Category("wallet", ("bifold wallet", "zip wallet", "card holder"), ("black", "brown", "dark brown", "tan", "navy",
             "maroon", "grey", "beige"), ("black", "white", "gold", "tan"), "with {c2} stitching", ("plain",), 0.2),
    Category("watch", ("wristwatch", "digital watch", "smartwatch"), METAL, ("black", "brown", "tan", "white",
             "navy", "silver"), "with a {c2} strap", ("plain",), 0.1, False, False),
)}
assert tuple(CATEGORY_SPECS) == CATEGORIES


@dataclass(frozen=True)
class Look:
    """The attributes a person would name; everything drawn is derived from these plus ``geometry_seed``."""

    variant: str
    colour: str
    colour2: str
    pattern: str = "plain"
    word: str | None = None
    scale: float = 1.0
    photo: str | None = None  # a print id (``prints.py``): a real photo printed on the front

    def key(self) -> tuple:
        return (self.variant, self.colour, self.colour2, self.pattern, self.word,
                prints.subject(self.photo) if self.photo else None)


@dataclass(frozen=True)
class ObjectSpec:
    object_id: str
    category: str
    split: str
    look: Look
    geometry_seed: int
    descriptions: tuple[str, ...] = field(default=())


def sample_look(cat: Category, rng: np.random.Generator, photos: tuple[str, ...]) -> Look:
    """A family's first member: kind, colours, pattern, and a photo print (or a word where no print fits)."""
    colour = str(rng.choice(cat.colours))
    colour2 = str(rng.choice([c for c in cat.colours2 if c != colour] or cat.colours2))
    pattern = str(rng.choice(cat.patterns)) if rng.random() < 0.3 + 0.5 * cat.spread else cat.patterns[0]
    photo = str(rng.choice(photos)) if cat.prints and photos else None
    word = str(rng.choice(WORDS)) if cat.words and photo is None else None
    return Look(str(rng.choice(cat.variants)), colour, colour2, pattern, word,
                float(np.exp(rng.normal(0, 0.04 + 0.12 * cat.spread))), photo)


def differences(cat: Category) -> tuple[str, ...]:
    """The ways siblings of one family differ, as real instances of a product do: the print, the colour, a part."""
    printed = ("print",) if cat.prints or cat.words else ()
    return (*printed, "colour", "part")


def vary(cat: Category, base: Look, kind: str, rng: np.random.Generator, taken: set[tuple],
         photos: tuple[str, ...]) -> Look:
    """A sibling of ``base`` that differs in one thing (``kind``): its print, its main colour, or a part's colour.

    Shape, proportions and everything else stay the family's, so siblings share their shape
    (the same ``geometry_seed`` draws the same proportions).
    """
    for _ in range(200):
        if kind == "print" and base.photo is not None:
            look = replace(base, photo=str(rng.choice(photos)))
        elif kind == "print":
            look = replace(base, word=str(rng.choice(WORDS)))
        elif kind == "colour":
            look = replace(base, colour=str(rng.choice([c for c in cat.colours if c != base.colour2])))
        else:
            look = replace(base, colour2=str(rng.choice([c for c in cat.colours2 if c != base.colour])))
        if look.key() not in taken:
            taken.add(look.key())
            return look
    raise ValueError(f"category {cat.name!r}: cannot draw another distinct instance; too many objects per category")


def family(cat: Category, count: int, rng: np.random.Generator, photos: tuple[str, ...]) -> list[Look]:
    """``count`` instances of one shape: the first as drawn, each other differing from it in one way, in turn."""
    base = sample_look(cat, rng, photos)
    taken = {base.key()}
    kinds = differences(cat)
    return [base, *(vary(cat, base, kinds[k % len(kinds)], rng, taken, photos) for k in range(count - 1))]


def make_objects(seed: int, per_category: int, val_fraction: float = 0.4) -> list[ObjectSpec]:
    """All instances, train first then val within each category, ids like ``mug_007``.

    Each split of a category is one family (``family``): same kind and shape, each sibling
    differing from the first in its print, colour or a part, so an episode's same-category
    look-alikes are what real look-alikes are, the same product in another version. Every
    category gets at least one val and one train instance (two of each from 4 per category
    on), so that episodes of both splits can hold same-category distractors.
    """
    if per_category < 2:
        raise SynthError(f"objects_per_category must be at least 2 (one train, one val), got {per_category}")
    n_val = min(per_category - 1, max(1, round(per_category * val_fraction)))
    specs = []
    for name in CATEGORIES:
        cat = CATEGORY_SPECS[name]
        looks: list[tuple[str, Look]] = []
        for split, count in (("train", per_category - n_val), ("val", n_val)):
            rng = np.random.default_rng(stable_seed(seed, "category", name, split))
            photos = tuple(p.print_id for p in prints.for_split(split))
            looks += [(split, look) for look in family(cat, count, rng, photos)]
        shape_seed = {split: stable_seed(seed, "geometry", name, split) for split in ("train", "val")}
        for k, (split, look) in enumerate(looks):
            object_id = f"{name.replace(' ', '_')}_{k:03d}"
            siblings = [other for s, other in looks if other is not look and s == split]
            rng_text = np.random.default_rng(stable_seed(seed, "describe", object_id))
            specs.append(ObjectSpec(object_id, name, split, look, shape_seed[split],
                                    describe(cat, look, siblings, rng_text)))
    return specs


# ------------------------------------------------------------------ descriptions
def _facts(look: Look) -> dict[str, str]:
    """The attributes beyond colour and kind that a description may mention."""
    facts = {"trim": look.colour2}
    if look.pattern != "plain":
        facts["pattern"] = f"{look.colour2} {look.pattern}"
    if look.word:
        facts["word"] = look.word
    if look.photo:
        facts["photo"] = prints.subject(look.photo)
    return facts


def _distinguishing(look: Look, siblings: list[Look], rng: np.random.Generator) -> list[str]:
    """A small random set of facts that, with colour and kind, no sibling shares.

    PIN's descriptions are short (10.7 words on average), so mention one or two details
    when that is enough to single the instance out, all of them otherwise.
    """
    facts = _facts(look)
    names = list(facts)
    rivals = [(s, _facts(s)) for s in siblings if (s.variant, s.colour) == (look.variant, look.colour)]

    def unique(chosen: list[str]) -> bool:
        return all(any(f.get(n) != facts[n] for n in chosen) for _, f in rivals)

    order = [str(n) for n in rng.permutation(names)]
    for size in (1, 2, 3):
        for start in range(len(order)):
            chosen = [order[(start + k) % len(order)] for k in range(min(size, len(order)))]
            if unique(chosen) and (size > 1 or not rivals or rng.random() < 0.7):
                return chosen
    return names


def _phrase(cat: Category, look: Look, fact: str, rng: np.random.Generator) -> str:
    if fact == "trim":
        return cat.trim.format(c2=look.colour2)
    if fact == "pattern":
        return str(rng.choice([f"with a {look.colour2} {look.pattern} pattern", f"with {look.colour2} {look.pattern} "
                               "decoration", f"covered in a {look.pattern} {look.colour2} pattern"]))
    if fact == "photo":
        subject = prints.subject(look.photo or "")
        a = "" if subject.endswith("s") else _article(subject) + " "
        return str(rng.choice([f"with a photo of {a}{subject} printed on it", f"with a printed picture of {a}{subject}",
                               f"with {a}{subject} photo print on the front"]))
    return str(rng.choice([f'with the word "{look.word}" written on it', f'with "{look.word}" printed on it',
                           f'with "{look.word}" on it']))


def _article(word: str) -> str:
    return "an" if word[0].lower() in "aeiou" else "a"


def describe(cat: Category, look: Look, siblings: list[Look], rng: np.random.Generator) -> tuple[str, str, str]:
    """Three PIN-style descriptions, each naming colour, kind and enough details to single the instance out."""
    noun = look.variant
    plural = noun.endswith(("sneakers", "boots", "shoes", "keys", "glasses"))
    size = "" if 0.9 < look.scale < 1.1 or any(w in noun for w in ("small", "big")) else (
        "small " if look.scale <= 0.9 else "large ")
    colour = "tortoiseshell-patterned" if look.colour == "tortoiseshell" else look.colour
    if plural:
        one = f"{size}{colour} {noun}" if noun == "keys" else f"a pair of {size}{colour} {noun}"
    else:
        one = f"{_article(size + colour)} {size}{colour} {noun}"

    def details() -> str:
        f = [_phrase(cat, look, name, rng) for name in _distinguishing(look, siblings, rng)]
        return f[0] if len(f) == 1 else ", ".join(f[:-1]) + " and " + f[-1]

    first = f"{one} {details()}"
    second = f"the {noun} {'are' if plural else 'is'} {colour} {details()}"
    third = rng.choice([f"this is my {colour} {noun}, {details()}", f"look for {one} {details()}",
                        f"{one}; it is the one {details()}"])
    return tuple(" ".join(s.split()) for s in (first, second, str(third)))  # type: ignore[return-value]
