#include "stillpoint/common/config_reader.hpp"

#include <fstream>
#include <functional>
#include <sstream>

namespace sp {

namespace {

// YAML text must be Unicode without C0 control characters other than tab, LF and CR. yaml-cpp 0.7
// does not check: fuzzing found inputs with NUL bytes or broken UTF-8 on which its scanner runs for
// minutes, so such files are refused here, with the line, before yaml-cpp sees them.
void check_yaml_text(const std::string& text, const std::string& origin) {
  int line = 1;
  for (std::size_t i = 0; i < text.size();) {
    const auto c = static_cast<unsigned char>(text[i]);
    if (c == '\n') ++line;
    if (c < 0x80) {
      if ((c < 0x20 && c != '\t' && c != '\n' && c != '\r') || c == 0x7f)
        throw InputError(origin, line, "control character " + std::to_string(c) + " in a YAML file");
      ++i;
      continue;
    }
    // UTF-8: lead byte gives the length; continuation bytes are 10xxxxxx; no overlong 2-byte forms.
    const std::size_t len = c >= 0xf0 && c <= 0xf4 ? 4 : c >= 0xe0 ? 3 : c >= 0xc2 && c <= 0xdf ? 2 : 0;
    bool ok = len != 0 && i + len <= text.size();
    for (std::size_t k = 1; ok && k < len; ++k) ok = (static_cast<unsigned char>(text[i + k]) & 0xc0) == 0x80;
    if (!ok) throw InputError(origin, line, "invalid UTF-8 in a YAML file");
    i += len;
  }
}

}  // namespace

ConfigReader::ConfigReader(std::shared_ptr<State> state, YAML::Node node, std::string prefix)
    : state_(std::move(state)), node_(std::move(node)), prefix_(std::move(prefix)) {}

ConfigReader ConfigReader::from_file(const std::filesystem::path& file) {
  if (!std::filesystem::exists(file)) throw ConfigError(file.string(), 0, "(file)", "file not found");
  auto state = std::make_shared<State>();
  state->file = file.string();
  std::ifstream in(file, std::ios::binary);
  if (!in) throw ConfigError(file.string(), 0, "(file)", "cannot open the file");
  std::stringstream buffer;
  buffer << in.rdbuf();
  const std::string text = buffer.str();
  check_yaml_text(text, file.string());
  try {
    state->root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw InputError(file.string(), e.mark.line + 1, "YAML syntax error: " + e.msg);
  } catch (const YAML::Exception& e) {
    throw InputError(file.string(), 0, std::string("cannot read YAML: ") + e.what());
  }
  if (state->root.IsNull()) state->root = YAML::Node(YAML::NodeType::Map);
  if (!state->root.IsMap()) throw InputError(file.string(), 1, "top level must be a mapping of keys");
  YAML::Node root = state->root;
  return ConfigReader(std::move(state), root, "");
}

ConfigReader ConfigReader::from_string(const std::string& text, const std::string& origin) {
  auto state = std::make_shared<State>();
  state->file = origin;
  check_yaml_text(text, origin);
  try {
    state->root = YAML::Load(text);
  } catch (const YAML::ParserException& e) {
    throw InputError(origin, e.mark.line + 1, "YAML syntax error: " + e.msg);
  } catch (const YAML::Exception& e) {
    throw InputError(origin, 0, std::string("cannot read YAML: ") + e.what());
  }
  if (state->root.IsNull()) state->root = YAML::Node(YAML::NodeType::Map);
  if (!state->root.IsMap()) throw InputError(origin, 1, "top level must be a mapping of keys");
  YAML::Node root = state->root;
  return ConfigReader(std::move(state), root, "");
}

bool ConfigReader::has(const std::string& key) const {
  return node_.IsMap() && node_[key] && !node_[key].IsNull();
}

std::string ConfigReader::path_of(const std::string& key) const {
  return prefix_.empty() ? key : prefix_ + "." + key;
}

void ConfigReader::mark_used(const std::string& key) const { state_->used.insert(path_of(key)); }

std::string ConfigReader::scalar_text(const std::string& key) const {
  const YAML::Node n = node_[key];
  return n.IsScalar() ? n.Scalar() : std::string("<non-scalar>");
}

int ConfigReader::line_of(const std::string& key) const {
  if (!node_.IsMap()) return 0;
  const YAML::Node n = node_[key];
  if (!n) return node_.Mark().line >= 0 ? node_.Mark().line + 1 : 0;
  return n.Mark().line >= 0 ? n.Mark().line + 1 : 0;
}

void ConfigReader::fail(const std::string& key, const std::string& what) const {
  throw ConfigError(state_->file, line_of(key), path_of(key), what);
}

void ConfigReader::read_choice(const std::string& key, std::string& field,
                               const std::vector<std::string>& allowed) const {
  read(key, field);
  for (const auto& a : allowed) {
    if (a == field) return;
  }
  std::string list;
  for (const auto& a : allowed) list += (list.empty() ? "" : ", ") + a;
  fail(key, "value '" + field + "' is not one of: " + list);
}

ConfigReader ConfigReader::section(const std::string& key) const {
  mark_used(key);
  if (!has(key)) return ConfigReader(state_, YAML::Node(YAML::NodeType::Map), path_of(key));
  YAML::Node child = node_[key];
  if (!child.IsMap()) fail(key, "must be a mapping of keys");
  return ConfigReader(state_, child, path_of(key));
}

void ConfigReader::finish() const {
  // Walk every key below this reader's node; the first one never read is an error.
  std::function<void(const YAML::Node&, const std::string&)> walk = [&](const YAML::Node& node,
                                                                        const std::string& prefix) {
    for (const auto& kv : node) {
      const int line = kv.first.Mark().line >= 0 ? kv.first.Mark().line + 1 : 0;
      if (!kv.first.IsScalar()) {
        throw ConfigError(state_->file, line, prefix.empty() ? "(top level)" : prefix,
                          "keys must be plain names");
      }
      const std::string key = kv.first.Scalar();
      const std::string full = prefix.empty() ? key : prefix + "." + key;
      if (!state_->used.contains(full)) {
        throw ConfigError(state_->file, line, full, "unknown key");
      }
      if (kv.second.IsMap()) walk(kv.second, full);
    }
  };
  if (node_.IsMap()) walk(node_, prefix_);
}

}  // namespace sp
