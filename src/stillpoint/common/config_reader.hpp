#pragma once
// Typed, validated reading of YAML configuration. Every error names the file, the key and the
// line; keys nobody reads are reported by finish(), so a typo never passes silently.
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "stillpoint/common/error.hpp"

namespace sp {

class ConfigReader {
 public:
  // Parses a YAML file; a missing file or a syntax error is a ConfigError naming the file.
  static ConfigReader from_file(const std::filesystem::path& file);
  // Parses YAML text (for tests and built-in presets); `origin` names it in errors.
  static ConfigReader from_string(const std::string& text, const std::string& origin);

  [[nodiscard]] bool has(const std::string& key) const;
  [[nodiscard]] const std::string& file() const noexcept { return state_->file; }
  [[nodiscard]] std::string path_of(const std::string& key) const;

  // A required key: missing is an error.
  template <typename T>
  T require(const std::string& key) const {
    if (!has(key)) fail(key, "missing required key");
    return convert<T>(key);
  }

  // An optional key: `field` keeps its default when the key is absent.
  template <typename T>
  void read(const std::string& key, T& field) const {
    if (has(key)) field = convert<T>(key);
  }

  // An optional key checked against [lo, hi].
  template <typename T>
  void read(const std::string& key, T& field, T lo, T hi) const {
    read(key, field);
    if (!(field >= lo && field <= hi)) {  // also rejects NaN
      fail(key, "value " + std::to_string(field) + " is out of range [" + std::to_string(lo) + ", " +
                    std::to_string(hi) + "]");
    }
  }

  // A required key checked against [lo, hi].
  template <typename T>
  T require(const std::string& key, T lo, T hi) const {
    T value = require<T>(key);
    if (!(value >= lo && value <= hi)) {  // also rejects NaN
      fail(key, "value " + std::to_string(value) + " is out of range [" + std::to_string(lo) + ", " +
                    std::to_string(hi) + "]");
    }
    return value;
  }

  // An optional key whose value must be one of `allowed`.
  void read_choice(const std::string& key, std::string& field, const std::vector<std::string>& allowed) const;

  // A nested mapping; an absent key gives an empty section (all defaults).
  [[nodiscard]] ConfigReader section(const std::string& key) const;

  // Throws ConfigError for the first key present in the document that nobody read.
  void finish() const;

  // Throws a ConfigError for `key` (for cross-field checks done by the caller).
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;

 private:
  struct State {
    std::string file;
    YAML::Node root;
    std::set<std::string> used;
  };
  ConfigReader(std::shared_ptr<State> state, YAML::Node node, std::string prefix);

  template <typename T>
  T convert(const std::string& key) const {
    mark_used(key);
    try {
      return node_[key].template as<T>();
    } catch (const YAML::Exception&) {
      fail(key, "cannot read '" + scalar_text(key) + "' as the expected type");
    }
  }
  void mark_used(const std::string& key) const;
  [[nodiscard]] std::string scalar_text(const std::string& key) const;
  [[nodiscard]] int line_of(const std::string& key) const;

  std::shared_ptr<State> state_;
  YAML::Node node_;
  std::string prefix_;
};

}  // namespace sp
