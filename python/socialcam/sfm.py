"""Structure from motion of a static scene through pycolmap (CPU), giving the camera poses
of social-camera frames in one world frame (the README's conventions).

>>> rec_dir = reconstruct_static("frames/", "work/sfm")        # doctest: +SKIP
>>> cams = Cameras.from_colmap(rec_dir)                          # doctest: +SKIP
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

CameraModel = Literal["SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL", "RADIAL", "OPENCV"]


def reconstruct_static(
    image_dir: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    camera_mode: Literal["single", "per_folder", "per_image"] = "single",
    camera_model: CameraModel = "SIMPLE_RADIAL",
    max_image_size: int = 1600,
    max_features: int = 4000,
    num_threads: int = -1,
    overwrite: bool = False,
    progress: Callable[[str], Any] | None = None,
) -> Path:
    """Runs incremental SfM on a folder of images and writes the largest model.

    Parameters
    ----------
    image_dir : folder of images (with ``camera_mode="per_folder"``, one sub-folder per
        social camera).
    out_dir : working folder; receives ``database.db`` and the model in ``sparse/``.
    camera_mode : ``"single"`` (one camera for all images: frames of one device — pycolmap's
        ``AUTO`` would give one camera per image), ``"per_folder"`` or
        ``"per_image"``.
    camera_model : COLMAP camera model for the intrinsics to estimate.
    max_image_size : images are downscaled to this size for SIFT; keypoints and intrinsics
        are reported at full resolution.
    max_features : SIFT features per image.
    num_threads : ``-1`` uses every core.
    overwrite : replace an existing ``out_dir``.
    progress : optional callback taking a stage name.

    Returns
    -------
    Path to the folder of the largest reconstruction, readable by
    :meth:`socialcam.Cameras.from_colmap`.

    Raises
    ------
    ValueError
        ``image_dir`` missing or without images, ``out_dir`` exists (without ``overwrite``).
    RuntimeError
        No model could be reconstructed.
    """
    try:
        import pycolmap
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise ImportError(
            "structure from motion needs pycolmap: pip install 'socialcam[sfm]'"
        ) from exc

    images = Path(image_dir)
    if not images.is_dir():
        raise ValueError(f"image_dir: {images} is not a folder")
    exts = {".jpg", ".jpeg", ".png", ".tif", ".tiff", ".bmp"}
    if not any(p.suffix.lower() in exts for p in images.rglob("*")):
        raise ValueError(f"image_dir: no images in {images}")
    if max_image_size < 64:
        raise ValueError(f"max_image_size: must be at least 64, got {max_image_size}")
    out = Path(out_dir)
    if out.exists():
        if not overwrite:
            raise ValueError(f"out_dir: {out} exists (pass overwrite=True to replace it)")
        shutil.rmtree(out)
    out.mkdir(parents=True)
    db = out / "database.db"
    say = progress or (lambda _stage: None)
    modes = {
        "single": pycolmap.CameraMode.SINGLE,
        "per_folder": pycolmap.CameraMode.PER_FOLDER,
        "per_image": pycolmap.CameraMode.PER_IMAGE,
    }
    if camera_mode not in modes:
        raise ValueError(f"camera_mode: expected one of {sorted(modes)}, got {camera_mode!r}")
    reader = pycolmap.ImageReaderOptions()
    reader.camera_model = camera_model
    extraction = pycolmap.FeatureExtractionOptions()
    extraction.num_threads = num_threads
    extraction.max_image_size = max_image_size
    extraction.sift.max_num_features = max_features
    say("features")
    pycolmap.extract_features(
        db,
        images,
        camera_mode=modes[camera_mode],
        reader_options=reader,
        extraction_options=extraction,
        device=pycolmap.Device.cpu,
    )
    matching = pycolmap.FeatureMatchingOptions()
    matching.num_threads = num_threads
    say("matching")
    pycolmap.match_exhaustive(db, matching_options=matching, device=pycolmap.Device.cpu)
    say("mapping")
    sparse = out / "sparse"
    sparse.mkdir()
    models = pycolmap.incremental_mapping(db, images, sparse)
    if not models:
        raise RuntimeError("structure from motion registered no model (too few matches?)")
    best = max(models, key=lambda k: models[k].num_reg_images())
    return sparse / str(best)
