#pragma once
// AWS Signature Version 4 for S3 requests (header-based authentication), as specified in the
// Amazon S3 API reference, "Signature Calculations for the Authorization Header":
//
//   canonical request = METHOD \n URI \n QUERY \n HEADERS \n SIGNED-HEADERS \n PAYLOAD-SHA256
//   string to sign    = "AWS4-HMAC-SHA256" \n DATE-TIME \n DATE/REGION/s3/aws4_request \n
//                       hex(SHA256(canonical request))
//   signing key       = HMAC(HMAC(HMAC(HMAC("AWS4" + secret, DATE), REGION), "s3"), "aws4_request")
//   signature         = hex(HMAC(signing key, string to sign))
//
// URI and query are URI-encoded with RFC 3986's unreserved characters kept (the URI's '/'
// kept too); headers are lower-cased, trimmed and sorted.

#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace hanzo::fusion::object_store {

struct SignableRequest {
  std::string method;                                        ///< "GET", "PUT", ...
  std::string path;                                          ///< unencoded, starting with '/': "/bucket/key"
  std::vector<std::pair<std::string, std::string>> query;    ///< unencoded name, value
  std::vector<std::pair<std::string, std::string>> headers;  ///< every header to sign, "host" included
  std::string payload_sha256;                                ///< lower-case hex
};

struct SigningKeys {
  std::string access_key_id;
  std::string secret_access_key;
};

/// The Authorization header's value for `request` at `amz_date` ("YYYYMMDDTHHMMSSZ", the
/// x-amz-date header's value, which `request.headers` must carry).
std::string authorization_header(const SignableRequest& request, const SigningKeys& keys, const std::string& region,
                                 const std::string& amz_date);

/// RFC 3986 percent-encoding (upper-case hex); '/' kept when `keep_slash`.
std::string uri_encode(std::string_view text, bool keep_slash);
/// Lower-case hex SHA-256.
std::string sha256_hex(std::string_view bytes);
/// The canonical query string: names and values encoded, sorted, joined with '&'.
std::string canonical_query(std::vector<std::pair<std::string, std::string>> query);

}  // namespace hanzo::fusion::object_store
