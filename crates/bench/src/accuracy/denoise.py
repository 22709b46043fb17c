# Denoises one image with Intel Open Image Denoise through PyPI's pyoidn (`pip install pyoidn
# numpy`), for `walkthrough-bench accuracy`'s denoised per-pixel competitor.
#
# usage: denoise.py WIDTH HEIGHT COLOR ALBEDO NORMAL OUT
# The four images are raw little-endian float32 RGB, row-major from the top-left pixel. Prints
# the seconds of one warm call ("high" quality, HDR colour, with albedo and normal): the first
# call loads the library and the network, which a viewport that keeps its filter pays once.
import sys
import time

import numpy as np
import pyoidn


def read(path, height, width):
    return np.fromfile(path, dtype="<f4").reshape(height, width, 3)


def main():
    width, height = int(sys.argv[1]), int(sys.argv[2])
    color, albedo, normal = (read(p, height, width) for p in sys.argv[3:6])
    pyoidn.denoise(color, albedo, normal, hdr=True, quality="high")
    started = time.perf_counter()
    out = pyoidn.denoise(color, albedo, normal, hdr=True, quality="high")
    seconds = time.perf_counter() - started
    np.ascontiguousarray(out, dtype="<f4").tofile(sys.argv[6])
    print(f"{seconds:.6f}")


if __name__ == "__main__":
    main()
