#include "stillpoint/report/ply_reader.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <fstream>
#include <sstream>

#include "stillpoint/common/error.hpp"

namespace sp::report {

namespace {

struct Property {
  std::string name;
  std::string type;
  int size = 0;
};

int type_size(const std::string& t) {
  if (t == "char" || t == "uchar" || t == "int8" || t == "uint8") return 1;
  if (t == "short" || t == "ushort" || t == "int16" || t == "uint16") return 2;
  if (t == "int" || t == "uint" || t == "float" || t == "int32" || t == "uint32" || t == "float32") return 4;
  if (t == "double" || t == "float64") return 8;
  return 0;
}

// One binary little-endian scalar as double.
double read_scalar(const char* p, const std::string& type) {
  char bytes[8];
  const int n = type_size(type);
  std::memcpy(bytes, p, static_cast<std::size_t>(n));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + n);
  auto as = [&bytes]<typename T>(T) {
    T v;
    std::memcpy(&v, bytes, sizeof(T));
    return static_cast<double>(v);
  };
  if (type == "char" || type == "int8") return as(std::int8_t{});
  if (type == "uchar" || type == "uint8") return as(std::uint8_t{});
  if (type == "short" || type == "int16") return as(std::int16_t{});
  if (type == "ushort" || type == "uint16") return as(std::uint16_t{});
  if (type == "int" || type == "int32") return as(std::int32_t{});
  if (type == "uint" || type == "uint32") return as(std::uint32_t{});
  if (type == "float" || type == "float32") return as(float{});
  return as(double{});
}

}  // namespace

PointCloud read_ply(const std::filesystem::path& file) {
  const std::string name = file.string();
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(name, 0, "cannot open the PLY file");
  std::string line;
  int line_no = 0;
  auto next_line = [&]() -> bool {
    if (!std::getline(in, line)) return false;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    return true;
  };
  if (!next_line() || line != "ply") throw InputError(name, 1, "not a PLY file (no 'ply' magic)");
  std::string format;
  std::size_t vertices = 0;
  bool in_vertex = false, seen_vertex = false;
  std::size_t elements_before_vertex = 0;
  std::vector<Property> props;
  while (true) {
    if (!next_line()) throw InputError(name, line_no, "header ends without end_header");
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "end_header") break;
    if (key == "comment" || key == "obj_info" || key.empty()) continue;
    if (key == "format") {
      std::string version;
      ls >> format >> version;
      if (format != "binary_little_endian" && format != "ascii")
        throw InputError(name, line_no,
                         "unsupported PLY format '" + format + "' (binary_little_endian or ascii)");
    } else if (key == "element") {
      std::string el;
      long long count = -1;
      ls >> el >> count;
      if (!ls || count < 0) throw InputError(name, line_no, "bad element line");
      in_vertex = el == "vertex";
      if (in_vertex) {
        seen_vertex = true;
        vertices = static_cast<std::size_t>(count);
      } else if (!seen_vertex && count > 0) {
        ++elements_before_vertex;
      }
    } else if (key == "property") {
      std::string type, pname;
      ls >> type;
      if (type == "list") throw InputError(name, line_no, "list properties are not supported");
      ls >> pname;
      if (!ls || type_size(type) == 0) throw InputError(name, line_no, "bad property line");
      if (in_vertex) props.push_back({pname, type, type_size(type)});
    } else {
      throw InputError(name, line_no, "unknown header keyword '" + key + "'");
    }
  }
  if (format.empty()) throw InputError(name, 0, "no format line in the header");
  if (!seen_vertex) throw InputError(name, 0, "no vertex element");
  if (elements_before_vertex > 0) throw InputError(name, 0, "elements before 'vertex' are not supported");
  int ix = -1, iy = -1, iz = -1, ir = -1, ig = -1, ib = -1;
  for (int i = 0; i < static_cast<int>(props.size()); ++i) {
    const std::string& n = props[static_cast<std::size_t>(i)].name;
    if (n == "x") ix = i;
    if (n == "y") iy = i;
    if (n == "z") iz = i;
    if (n == "red" || n == "r") ir = i;
    if (n == "green" || n == "g") ig = i;
    if (n == "blue" || n == "b") ib = i;
  }
  if (ix < 0 || iy < 0 || iz < 0) throw InputError(name, 0, "vertex element has no x, y, z");
  const bool colour = ir >= 0 && ig >= 0 && ib >= 0;

  PointCloud cloud;
  cloud.xyz.reserve(vertices * 3);
  if (colour) cloud.rgb.reserve(vertices * 3);
  std::vector<double> values(props.size());
  auto keep = [&]() {
    for (int i : {ix, iy, iz}) cloud.xyz.push_back(static_cast<float>(values[static_cast<std::size_t>(i)]));
    if (colour)
      for (int i : {ir, ig, ib})
        cloud.rgb.push_back(
            static_cast<std::uint8_t>(std::clamp(values[static_cast<std::size_t>(i)], 0.0, 255.0)));
  };
  if (format == "ascii") {
    for (std::size_t v = 0; v < vertices; ++v) {
      if (!next_line()) throw InputError(name, line_no, "file ends after " + std::to_string(v) + " vertices");
      std::istringstream ls(line);
      for (double& x : values) ls >> x;
      if (!ls) throw InputError(name, line_no, "bad vertex line");
      keep();
    }
    return cloud;
  }
  std::size_t stride = 0;
  for (const Property& p : props) stride += static_cast<std::size_t>(p.size);
  std::vector<char> data(stride * vertices);
  in.read(data.data(), static_cast<std::streamsize>(data.size()));
  if (static_cast<std::size_t>(in.gcount()) != data.size())
    throw InputError(
        name, 0,
        "truncated: header says " + std::to_string(vertices) + " vertices, data holds " +
            std::to_string(static_cast<std::size_t>(in.gcount()) / std::max<std::size_t>(stride, 1)));
  for (std::size_t v = 0; v < vertices; ++v) {
    const char* p = data.data() + v * stride;
    for (std::size_t i = 0; i < props.size(); ++i) {
      values[i] = read_scalar(p, props[i].type);
      p += props[i].size;
    }
    keep();
  }
  return cloud;
}

}  // namespace sp::report
