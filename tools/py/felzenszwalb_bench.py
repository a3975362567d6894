"""Time scikit-image's felzenszwalb segmentation on a raw 8-bit image.

Usage: felzenszwalb_bench.py RAW WIDTH HEIGHT BANDS RUNS
RAW holds WIDTH*HEIGHT*BANDS bytes, pixel-interleaved, row-major (as
`relevo-bench veg` writes it). Prints one JSON object: the median time in
milliseconds and the number of segments.
"""
import json
import sys
import time

import numpy as np
from skimage.segmentation import felzenszwalb


def main():
    raw, width, height, bands, runs = sys.argv[1], *map(int, sys.argv[2:6])
    image = np.fromfile(raw, dtype=np.uint8).reshape(height, width, bands)
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        labels = felzenszwalb(image, scale=100, sigma=0.5, min_size=16)
        times.append((time.perf_counter() - start) * 1e3)
    print(json.dumps({"ms": float(np.median(times)), "segments": int(labels.max()) + 1,
                      "skimage": __import__("skimage").__version__}))


if __name__ == "__main__":
    main()
