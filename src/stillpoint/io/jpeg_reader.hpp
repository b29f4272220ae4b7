#pragma once
// Colour JPEG files decoded straight to BGR by libjpeg-turbo (JCS_EXT_BGR). OpenCV 4.6 as Debian builds
// it decodes to RGB and swaps the bytes of every pixel in a scalar loop: ~5 % of a whole run's CPU in
// `perf`, on the reader thread that shares the cores with tracking. Same pixels as cv::imread.
#include <opencv2/core.hpp>
#include <string>

namespace sp::io {

// The image as cv::imread(path, cv::IMREAD_COLOR) gives it. Three-component baseline/progressive JPEGs
// without EXIF data are decoded here; anything else (other formats, grey or CMYK JPEGs, EXIF
// orientation, libjpeg built without BGR output, a corrupt file) goes to cv::imdecode of the same
// bytes (the file is read once). Empty when unreadable, as cv::imread.
cv::Mat read_color_image(const std::string& path);

// Whether this build decodes JPEGs itself (libjpeg-turbo found at build time).
bool direct_jpeg_decoding();

// Only the direct decode: empty when the file is not a JPEG it takes (the cases above).
cv::Mat decode_jpeg_bgr(const std::string& path);

}  // namespace sp::io
