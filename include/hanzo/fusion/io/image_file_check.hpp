#pragma once
// Whether an image file holds the whole image. Decoders fill what a cut-off file lacks (libjpeg
// pads a truncated JPEG with grey and only prints "Premature end of JPEG file"), so a reader
// that must see every pixel (the privacy filter, the importers) checks the file's structure
// first:
//   JPEG: the markers from SOI are walked (segment lengths; entropy-coded data after each SOS up
//         to the next marker) and the file must reach EOI (0xFFD9). Bytes after EOI (camera
//         trailers) are allowed.
//   PNG:  the chunks from the signature are walked (length, type, CRC skipped) and must reach
//         IEND.
// Other formats are not checked (their decoders fail on truncation). Failures name the file and
// what is missing, e.g. "a.jpg: truncated JPEG: the data ends at byte 8192 before the end-of-image
// marker".

#include <string>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::io {

/// Whether the file name has an extension of the image formats the readers take (png, jpg,
/// jpeg, bmp, tif, tiff, pgm, ppm, pnm, webp; any case): the image folders of importers and of
/// the vision and privacy commands.
bool has_image_extension(const std::string& path);

/// Checks the bytes of an image file (its name is only for the message).
Status check_image_complete(const std::string& bytes, const std::string& name);
/// Reads `path` and checks it.
Status check_image_file_complete(const std::string& path);

}  // namespace hanzo::fusion::io
