#!/usr/bin/env python3
"""Checks a frame's PNG against PyOpenColorIO: the EXR's composite (its default layer R, G, B) through the
same config, display, view and looks (a .cube becoming the look `flarelab_cube` in the config's color_timing
space, as FlareLab makes it), clamped to [0, 1] and rounded to 8 bits, must equal the PNG within 1/255.

Usage: ocio_reference.py FRAME.exr FRAME.png [--config C] [--display D] [--view V] [--looks L] [--cube F]
Exit status: 0 when within 1/255, 1 when not, 2 when PyOpenColorIO or OpenEXR is missing (the caller skips).
Prints the largest difference in 8-bit steps.
"""
import argparse
import os
import sys

try:
    import numpy as np
    import OpenEXR
    import PyOpenColorIO as ocio
    from PIL import Image
except ImportError as e:  # pragma: no cover - reported to the caller
    print(f"missing: {e}")
    sys.exit(2)

WORKING_SPACE = "Linear Rec.709 (sRGB)"
CUBE_LOOK = "flarelab_cube"


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("exr")
    parser.add_argument("png")
    parser.add_argument("--config", default="ocio://studio-config-latest")
    parser.add_argument("--display")
    parser.add_argument("--view")
    parser.add_argument("--looks", default="")
    parser.add_argument("--cube")
    args = parser.parse_args()

    config = ocio.Config.CreateFromFile(args.config)
    display = args.display or config.getDefaultDisplay()
    view = args.view or config.getDefaultView(display)
    looks = [l.strip() for l in args.looks.split(",") if l.strip()]
    if args.cube:
        space = "color_timing" if config.hasRole("color_timing") else "scene_linear"
        config.addLook(ocio.Look(name=CUBE_LOOK, processSpace=space,
                                 transform=ocio.FileTransform(src=os.path.abspath(args.cube))))
        looks.append(CUBE_LOOK)
    pipeline = ocio.LegacyViewingPipeline()
    pipeline.setDisplayViewTransform(ocio.DisplayViewTransform(src=WORKING_SPACE, display=display, view=view))
    if looks:
        pipeline.setLooksOverrideEnabled(True)
        pipeline.setLooksOverride(", ".join(looks))
    cpu = pipeline.getProcessor(config).getDefaultCPUProcessor()

    exr = OpenEXR.File(args.exr)
    channels = exr.parts[0].channels
    rgba = channels["RGBA"].pixels if "RGBA" in channels else channels["RGB"].pixels
    rgb = np.ascontiguousarray(rgba[..., :3], dtype=np.float32)
    rgb = np.where(np.isfinite(rgb), rgb, 0.0).astype(np.float32)
    cpu.applyRGB(rgb)
    expected = np.floor(np.clip(np.nan_to_num(rgb), 0.0, 1.0) * 255.0 + 0.5).astype(int)
    png = np.asarray(Image.open(args.png).convert("RGB")).astype(int)
    worst = int(np.abs(expected - png).max())
    print(f"{display} / {view} / looks [{', '.join(looks)}]: worst difference {worst}/255")
    sys.exit(0 if worst <= 1 else 1)


if __name__ == "__main__":
    main()
