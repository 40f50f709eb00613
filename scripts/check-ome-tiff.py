#!/usr/bin/python3
"""Reads an OME-TIFF with tifffile and prints what an independent reader sees: shape, axes, dtype,
physical sizes, channels and exposure. Not part of ctest (the C++ tests do not depend on Python).

Usage: /usr/bin/python3 scripts/check-ome-tiff.py FILE [FILE ...]
Needs Debian's python3-tifffile and python3-numpy. Files to try it on: run the C++ test with
FLUOROSIM_KEEP_OME_TIFF=DIR fluorosim_tests --gtest_filter=OmeTiff.DetectorStack, which leaves
DIR/detector_stack.ome.tif (uint16 counts) and DIR/detector_expected.ome.tif (float32 electrons).
Exits with 1 if a file is not read as OME or its series shape disagrees with the OME-XML sizes.
"""
import sys

import tifffile


def as_list(x):
    return x if isinstance(x, list) else [x]


def check(path):
    ok = True
    with tifffile.TiffFile(path) as tif:
        print(f"{path}:")
        print(f"  is_ome: {tif.is_ome}, pages: {len(tif.pages)}, bigtiff: {tif.is_bigtiff}")
        series = tif.series[0]
        data = series.asarray()
        print(f"  series[0]: shape {series.shape}, axes {series.axes}, dtype {series.dtype}, "
              f"min {data.min()}, max {data.max()}")
        if not tif.is_ome:
            print("  NOT read as OME-TIFF")
            return False
        ome = tifffile.xml2dict(tif.ome_metadata)["OME"]
        image = as_list(ome["Image"])[0]
        pixels = image["Pixels"]
        print(f"  DimensionOrder {pixels['DimensionOrder']}, Type {pixels['Type']}, "
              f"SizeX/Y/Z/C/T {pixels['SizeX']}/{pixels['SizeY']}/{pixels['SizeZ']}/{pixels['SizeC']}/{pixels['SizeT']}")
        for axis in "XYZ":
            print(f"  PhysicalSize{axis} = {pixels.get('PhysicalSize' + axis)} {pixels.get('PhysicalSize' + axis + 'Unit')}")
        for ch in as_list(pixels.get("Channel", [])):
            print(f"  Channel {ch.get('Name')!r}: excitation {ch.get('ExcitationWavelength')} "
                  f"{ch.get('ExcitationWavelengthUnit')}, emission {ch.get('EmissionWavelength')} "
                  f"{ch.get('EmissionWavelengthUnit')}")
        planes = as_list(pixels.get("Plane", []))
        exposures = sorted({(p.get("ExposureTime"), p.get("ExposureTimeUnit")) for p in planes})
        print(f"  Plane elements: {len(planes)}, exposure times: {exposures}")
        expected = {"X": pixels["SizeX"], "Y": pixels["SizeY"], "Z": pixels["SizeZ"], "C": pixels["SizeC"],
                    "T": pixels["SizeT"]}
        for axis, size in zip(series.axes, series.shape):
            if axis in expected and expected[axis] != size:
                print(f"  MISMATCH: axis {axis} has {size} samples, OME-XML says {expected[axis]}")
                ok = False
    return ok


def main():
    if len(sys.argv) < 2:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    return 0 if all([check(p) for p in sys.argv[1:]]) else 1


if __name__ == "__main__":
    sys.exit(main())
