#include "s3_xml.hpp"

#include <cstdint>

#include <fmt/format.h>

namespace hanzo::fusion::object_store::xml {
namespace {

void append_utf8(std::string& out, uint32_t code_point) {
  if (code_point < 0x80) {
    out.push_back(static_cast<char>(code_point));
  } else if (code_point < 0x800) {
    out.push_back(static_cast<char>(0xc0 | (code_point >> 6)));
    out.push_back(static_cast<char>(0x80 | (code_point & 0x3f)));
  } else if (code_point < 0x10000) {
    out.push_back(static_cast<char>(0xe0 | (code_point >> 12)));
    out.push_back(static_cast<char>(0x80 | ((code_point >> 6) & 0x3f)));
    out.push_back(static_cast<char>(0x80 | (code_point & 0x3f)));
  } else if (code_point < 0x110000) {
    out.push_back(static_cast<char>(0xf0 | (code_point >> 18)));
    out.push_back(static_cast<char>(0x80 | ((code_point >> 12) & 0x3f)));
    out.push_back(static_cast<char>(0x80 | ((code_point >> 6) & 0x3f)));
    out.push_back(static_cast<char>(0x80 | (code_point & 0x3f)));
  }
}

std::string decode(std::string_view text) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    const auto end = text[i] == '&' ? text.find(';', i) : std::string_view::npos;
    if (end == std::string_view::npos || end - i > 10) {
      out.push_back(text[i]);
      continue;
    }
    const std::string_view entity = text.substr(i + 1, end - i - 1);
    if (entity == "amp") {
      out.push_back('&');
    } else if (entity == "lt") {
      out.push_back('<');
    } else if (entity == "gt") {
      out.push_back('>');
    } else if (entity == "quot") {
      out.push_back('"');
    } else if (entity == "apos") {
      out.push_back('\'');
    } else if (entity.size() > 1 && entity[0] == '#') {
      const bool hex = entity[1] == 'x' || entity[1] == 'X';
      uint32_t value = 0;
      bool valid = entity.size() > (hex ? 2u : 1u);
      for (std::size_t j = hex ? 2 : 1; j < entity.size() && valid; ++j) {
        const char c = entity[j];
        const int digit = (c >= '0' && c <= '9') ? c - '0' : (hex && c >= 'a' && c <= 'f') ? c - 'a' + 10 : (hex && c >= 'A' && c <= 'F') ? c - 'A' + 10 : -1;
        valid = digit >= 0 && value < 0x110000;
        value = value * (hex ? 16 : 10) + static_cast<uint32_t>(digit);
      }
      if (!valid) {
        out.push_back(text[i]);
        continue;
      }
      append_utf8(out, value);
    } else {
      out.push_back(text[i]);
      continue;
    }
    i = end;
  }
  return out;
}

}  // namespace

std::vector<std::string_view> elements(std::string_view document, std::string_view name) {
  std::vector<std::string_view> found;
  const std::string open = fmt::format("<{}", name);
  const std::string close = fmt::format("</{}>", name);
  for (std::size_t at = document.find(open); at != std::string_view::npos; at = document.find(open, at)) {
    const std::size_t after_name = at + open.size();
    // "<Key>" or "<Key attr=...>", not "<KeyMarker>"; "<Key/>" is empty.
    if (after_name >= document.size() || (document[after_name] != '>' && document[after_name] != ' ' && document[after_name] != '/')) {
      at = after_name;
      continue;
    }
    const std::size_t tag_end = document.find('>', after_name);
    if (tag_end == std::string_view::npos) break;
    if (document[tag_end - 1] == '/') {
      found.emplace_back();
      at = tag_end + 1;
      continue;
    }
    const std::size_t end = document.find(close, tag_end + 1);
    if (end == std::string_view::npos) break;
    found.push_back(document.substr(tag_end + 1, end - tag_end - 1));
    at = end + close.size();
  }
  return found;
}

std::string text(std::string_view document, std::string_view name) {
  const std::vector<std::string_view> found = elements(document, name);
  return found.empty() ? std::string{} : decode(found.front());
}

std::string escape(std::string_view text) {
  std::string out;
  for (const char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out.push_back(c);
    }
  }
  return out;
}

}  // namespace hanzo::fusion::object_store::xml
