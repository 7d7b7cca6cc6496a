#pragma once
// The web viewer's files (web/src, the script bundled with three.js by esbuild at build time),
// compiled into the server by cmake/embed_web_assets.cmake and served by the REST server.
#include <span>
#include <string_view>

namespace hanzo::fusion::service::detail {

struct WebAsset {
  std::string_view path;          // "/", "/viewer.js", "/viewer.css"
  std::string_view content_type;
  std::string_view body;
};

std::span<const WebAsset> web_assets();

}  // namespace hanzo::fusion::service::detail
