#include "stillpoint/io/jpeg_reader.hpp"

#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#ifdef SP_HAVE_LIBJPEG
#include <jpeglib.h>
#endif

namespace sp::io {

namespace {

// The file's bytes (empty when unreadable): read once, for the direct decoder and the fallback alike.
std::vector<unsigned char> read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

#if defined(SP_HAVE_LIBJPEG) && defined(JCS_EXTENSIONS)
struct ErrorManager {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
};

void on_error(j_common_ptr cinfo) { std::longjmp(reinterpret_cast<ErrorManager*>(cinfo->err)->jump, 1); }
void no_message(j_common_ptr /*cinfo*/) {}

bool has_exif(const jpeg_decompress_struct& cinfo) {
  for (jpeg_saved_marker_ptr m = cinfo.marker_list; m != nullptr; m = m->next)
    if (m->marker == JPEG_APP0 + 1 && m->data_length >= 6 && std::memcmp(m->data, "Exif\0\0", 6) == 0)
      return true;
  return false;
}

// Only plain C objects live in this frame (longjmp skips destructors); `out` is the caller's.
bool decode(const unsigned char* data, std::size_t size, cv::Mat& out) {
  jpeg_decompress_struct cinfo;
  ErrorManager err;
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = on_error;
  err.pub.output_message = no_message;
  if (setjmp(err.jump)) {
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, data, static_cast<unsigned long>(size));
  jpeg_save_markers(&cinfo, JPEG_APP0 + 1, 0xffff);
  jpeg_read_header(&cinfo, TRUE);
  // cv::imread turns EXIF-rotated images upright and converts grey / CMYK itself: left to it.
  if (cinfo.num_components != 3 || has_exif(cinfo)) {
    jpeg_destroy_decompress(&cinfo);
    return false;
  }
  cinfo.out_color_space = JCS_EXT_BGR;
  jpeg_start_decompress(&cinfo);
  out.create(static_cast<int>(cinfo.output_height), static_cast<int>(cinfo.output_width), CV_8UC3);
  while (cinfo.output_scanline < cinfo.output_height) {
    JSAMPROW row = out.ptr<unsigned char>(static_cast<int>(cinfo.output_scanline));
    jpeg_read_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_decompress(&cinfo);
  jpeg_destroy_decompress(&cinfo);
  return true;
}

cv::Mat decode_bytes(const std::vector<unsigned char>& bytes) {
  if (bytes.size() < 4 || bytes[0] != 0xFF || bytes[1] != 0xD8) return {};  // no JPEG start-of-image
  cv::Mat out;
  if (!decode(bytes.data(), bytes.size(), out)) return {};
  return out;
}
#else
cv::Mat decode_bytes(const std::vector<unsigned char>& /*bytes*/) { return {}; }
#endif

}  // namespace

cv::Mat decode_jpeg_bgr(const std::string& path) { return decode_bytes(read_bytes(path)); }

bool direct_jpeg_decoding() {
#if defined(SP_HAVE_LIBJPEG) && defined(JCS_EXTENSIONS)
  return true;
#else
  return false;
#endif
}

cv::Mat read_color_image(const std::string& path) {
  const std::vector<unsigned char> bytes = read_bytes(path);
  if (bytes.empty()) return {};
  cv::Mat img = decode_bytes(bytes);
  if (img.empty()) img = cv::imdecode(bytes, cv::IMREAD_COLOR);
  return img;
}

}  // namespace sp::io
