"""Batch norms folded into their convolutions: the same function, no norm left, nothing folded that must not be."""

import pytest
import torch
from torch import nn

from pin_match.nn.fold import FoldWarning, fold_batch_norms


def _randomise_norms(model: nn.Module) -> None:
    gen = torch.Generator().manual_seed(0)
    for m in model.modules():
        if isinstance(m, nn.BatchNorm2d):
            if m.track_running_stats:
                m.running_mean.copy_(torch.randn(m.num_features, generator=gen) * 0.5)
                m.running_var.copy_(torch.rand(m.num_features, generator=gen) + 0.5)
            if m.affine:
                m.weight.data.copy_(torch.randn(m.num_features, generator=gen) * 0.2 + 1)
                m.bias.data.copy_(torch.randn(m.num_features, generator=gen) * 0.2)


def _folded_against_original(model: nn.Module) -> tuple[int, float, nn.Module]:
    _randomise_norms(model)
    model.eval()
    x = torch.randn(2, 3, 32, 32, generator=torch.Generator().manual_seed(1))
    with torch.inference_mode():
        before = model(x).clone()
    count = fold_batch_norms(model, torch.randn(1, 3, 32, 32, generator=torch.Generator().manual_seed(2)))
    with torch.inference_mode():
        after = model(x)
    return count, float((after - before).abs().max()), model


def test_timm_norm_and_activation_modules_fold_and_keep_their_activation():
    from timm.layers import BatchNormAct2d

    model = nn.Sequential(nn.Conv2d(3, 8, 3, padding=1, bias=False), BatchNormAct2d(8, act_layer=nn.ReLU6),
                          nn.Conv2d(8, 8, 3, padding=1, groups=8, bias=True), BatchNormAct2d(8, act_layer=nn.ReLU6),
                          nn.Conv2d(8, 4, 1, bias=False), BatchNormAct2d(4, apply_act=False))
    count, diff, folded = _folded_against_original(model)
    assert count == 3 and diff < 1e-5
    assert not any(isinstance(m, nn.BatchNorm2d) for m in folded.modules())
    assert isinstance(folded[1].act, nn.ReLU6) and folded[2].bias is not None


def test_torchvision_mobilenet_folds_whole():
    from torchvision.models import mobilenet_v2

    count, diff, folded = _folded_against_original(mobilenet_v2().features[:4])
    assert count == 9 and diff < 1e-4  # the stem, 2 + 3 + 3 in the first three blocks
    assert not any(isinstance(m, nn.BatchNorm2d) for m in folded.modules())


class _TwoReaders(nn.Module):
    """A convolution whose output a norm and another module both read: folding would change the other reader."""

    def __init__(self) -> None:
        super().__init__()
        self.conv, self.norm, self.side = nn.Conv2d(3, 4, 1), nn.BatchNorm2d(4), nn.ReLU()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.conv(x)
        return self.norm(y) + self.side(y)


def test_a_convolution_read_twice_and_a_norm_without_convolution_stay():
    count, diff, folded = _folded_against_original(_TwoReaders())
    assert count == 0 and diff == 0 and isinstance(folded.norm, nn.BatchNorm2d)
    count, _, folded = _folded_against_original(nn.Sequential(nn.BatchNorm2d(3), nn.Conv2d(3, 4, 1)))
    assert count == 0 and isinstance(folded[0], nn.BatchNorm2d)


def test_a_norm_without_running_statistics_stays_and_one_without_affine_weights_folds():
    """The first divides by each batch's own statistics in eval mode too: no weight can hold them."""
    count, diff, folded = _folded_against_original(
        nn.Sequential(nn.Conv2d(3, 4, 3, padding=1), nn.BatchNorm2d(4, track_running_stats=False)))
    assert count == 0 and diff == 0 and isinstance(folded[1], nn.BatchNorm2d)
    count, diff, folded = _folded_against_original(
        nn.Sequential(nn.Conv2d(3, 4, 3, padding=1, bias=False), nn.BatchNorm2d(4, affine=False), nn.ReLU()))
    assert count == 1 and diff < 1e-5 and isinstance(folded[1], nn.Identity)


class _PlainReader(nn.Module):
    """A convolution whose output a norm reads and so does a plain function, which no hook sees."""

    def __init__(self) -> None:
        super().__init__()
        self.conv, self.norm = nn.Conv2d(3, 4, 1), nn.BatchNorm2d(4)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = self.conv(x)
        return self.norm(y) + torch.relu(y)


def test_a_plain_function_reading_a_convolution_leaves_the_network_unfolded_with_a_warning():
    with pytest.warns(FoldWarning, match="left unfolded"):
        count, diff, folded = _folded_against_original(_PlainReader())
    assert count == 0 and diff == 0  # put back as it was: the very parameters, the norm in its place
    assert isinstance(folded.norm, nn.BatchNorm2d) and folded.conv.bias is not None


def test_a_network_in_training_mode_is_refused():
    with pytest.raises(ValueError, match="eval mode"):
        fold_batch_norms(nn.Sequential(nn.Conv2d(3, 4, 1), nn.BatchNorm2d(4)), torch.zeros(1, 3, 8, 8))
