// Fuzz target: what an S3-compatible server answers (object_store's XML reader: listings,
// multipart upload ids, error documents) and object keys. The first byte picks what the rest
// is: an S3 response document read as the client reads it, an object key to validate, or text
// that must come back exactly through escape() and text() (the round trip the multipart
// manifest relies on).

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string>

#include "hanzo/fusion/object_store/object_store.hpp"
#include "s3_xml.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion::object_store;
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (data[0] % 3) {
    case 0: {
      for (const std::string_view entry : xml::elements(text, "Contents")) {
        (void)xml::text(entry, "Key");
        (void)xml::text(entry, "Size");
        (void)xml::text(entry, "LastModified");
      }
      (void)xml::text(text, "IsTruncated");
      (void)xml::text(text, "NextContinuationToken");
      (void)xml::text(text, "UploadId");
      (void)xml::text(text, "Code");
      (void)xml::text(text, "Message");
      break;
    }
    case 1:
      (void)validate_object_key(text);
      break;
    default:
      if (xml::text("<ETag>" + xml::escape(text) + "</ETag>", "ETag") != text) std::abort();
  }
  return 0;
}
