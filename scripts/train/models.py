"""The two model families of the baseline, both built from scratch (no pretrained weights).

- `unet`: bottom-up. A U-Net predicts per pixel background / interior / rim logits and a distance-to-edge
  map; instances come from a watershed of the distance map seeded by confident interior cores
  (`instances.py`). Cheap, dense, good at building-vs-background.
- `maskrcnn`: top-down. torchvision's Mask R-CNN on a ResNet-18 FPN with trainable BatchNorm, weights
  and backbone weights both `None`: boxes first, then a mask per box, so touching buildings are separate
  detections by construction.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

FAMILIES = ("unet", "maskrcnn")


class ConvBlock(nn.Sequential):
    def __init__(self, cin: int, cout: int):
        super().__init__(
            nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
            nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
        )


class UNet(nn.Module):
    """U-Net with `levels` down-samplings; output: 3 class logits + 1 distance logit per pixel.

    Inputs must have sides divisible by 2**levels (`pad_to` does that).
    """

    def __init__(self, width: int = 32, levels: int = 4):
        super().__init__()
        chans = [width * 2 ** i for i in range(levels + 1)]
        self.levels = levels
        self.stem = ConvBlock(3, chans[0])
        self.down = nn.ModuleList(ConvBlock(chans[i], chans[i + 1]) for i in range(levels))
        self.up = nn.ModuleList(nn.ConvTranspose2d(chans[i + 1], chans[i], 2, stride=2)
                                for i in reversed(range(levels)))
        self.fuse = nn.ModuleList(ConvBlock(2 * chans[i], chans[i]) for i in reversed(range(levels)))
        self.head = nn.Conv2d(chans[0], 4, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = [self.stem(x)]
        for block in self.down:
            skips.append(block(F.max_pool2d(skips[-1], 2)))
        y = skips.pop()
        for up, fuse in zip(self.up, self.fuse):
            y = fuse(torch.cat([up(y), skips.pop()], dim=1))
        return self.head(y)


def pad_to(x: torch.Tensor, multiple: int) -> tuple[torch.Tensor, tuple[int, int]]:
    """Pads (…, h, w) at the bottom/right to multiples of `multiple` (reflect); returns the original size."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    if ph or pw:
        x = F.pad(x, (0, pw, 0, ph), mode="reflect" if min(h, w) > max(ph, pw) else "replicate")
    return x, (h, w)


def mask_rcnn(image_size: tuple[int, int]) -> nn.Module:
    """Mask R-CNN (2 classes: background, building) on a ResNet-18 FPN, from scratch.

    The transform keeps the frames at their own size (min/max size = the frame's sides); the anchors
    (one size per FPN level, three aspect ratios) start at 1/32 of the short side, at least 8 px, since
    aerial buildings are small: torchvision's defaults (32–512 px) miss most of them.
    """
    from torchvision.models.detection import MaskRCNN
    from torchvision.models.detection.anchor_utils import AnchorGenerator
    from torchvision.models.detection.backbone_utils import resnet_fpn_backbone

    backbone = resnet_fpn_backbone(backbone_name="resnet18", weights=None, trainable_layers=5,
                                   norm_layer=nn.BatchNorm2d)
    h, w = image_size
    base = max(8, 2 ** round(math.log2(max(min(h, w) / 32, 1))))
    anchors = AnchorGenerator(tuple((base * 2 ** i,) for i in range(5)), ((0.5, 1.0, 2.0),) * 5)
    return MaskRCNN(backbone, num_classes=2, min_size=min(h, w), max_size=max(h, w), rpn_anchor_generator=anchors,
                    box_detections_per_img=200, rpn_batch_size_per_image=256,
                    box_batch_size_per_image=256)


def build(family: str, width: int, image_size: tuple[int, int]) -> nn.Module:
    if family == "unet":
        return UNet(width=width)
    if family == "maskrcnn":
        return mask_rcnn(image_size)
    raise ValueError(f"unknown model family {family!r} (one of {', '.join(FAMILIES)})")
