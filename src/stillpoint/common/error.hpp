#pragma once
// Error types that carry where bad input came from, so a user can fix the file they own.
#include <stdexcept>
#include <string>

namespace sp {

// Base of every error StillPoint throws on purpose.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Bad content in an input file: the message names the file and (when known) the 1-based line.
class InputError : public Error {
 public:
  InputError(std::string file, int line, const std::string& what)
      : Error(format(file, line, what)), file_(std::move(file)), line_(line) {}
  [[nodiscard]] const std::string& file() const noexcept { return file_; }
  [[nodiscard]] int line() const noexcept { return line_; }

 private:
  static std::string format(const std::string& file, int line, const std::string& what) {
    return line > 0 ? file + ":" + std::to_string(line) + ": " + what : file + ": " + what;
  }
  std::string file_;
  int line_;
};

// A wrong configuration value: names the file, the key and (when known) the line.
class ConfigError : public InputError {
 public:
  ConfigError(std::string file, int line, const std::string& key, const std::string& what)
      : InputError(std::move(file), line, "key '" + key + "': " + what), key_(key) {}
  [[nodiscard]] const std::string& key() const noexcept { return key_; }

 private:
  std::string key_;
};

}  // namespace sp
