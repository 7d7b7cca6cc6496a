#pragma once
// The little XML the S3 API answers with (ListBucketResult, InitiateMultipartUploadResult,
// Error): elements are found by name, text has its five predefined entities and numeric
// character references decoded. Enough for S3's flat documents; not a general XML parser.

#include <string>
#include <string_view>
#include <vector>

namespace hanzo::fusion::object_store::xml {

/// The contents of every <name>...</name> element, in document order (not nested in each other).
std::vector<std::string_view> elements(std::string_view document, std::string_view name);
/// The decoded text of the first <name> element; empty when there is none.
std::string text(std::string_view document, std::string_view name);
/// Escapes &, <, >, " and ' for element text.
std::string escape(std::string_view text);

}  // namespace hanzo::fusion::object_store::xml
