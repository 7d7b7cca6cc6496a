// Signs S3 requests with Amazon's own Signature Version 4 implementation (@smithy/signature-v4,
// the signer of the AWS SDK for JavaScript v3), for tests/object_store/object_store_test.cpp.
//   node sigv4_sign.mjs REQUESTS.json   prints a JSON list of Authorization header values
// Each request: {method, path (unencoded, "/bucket/key"), query {name: value}, headers {name:
// value} (host and x-amz-content-sha256 included), access_key, secret, region, amz_date}.
import { readFileSync } from "node:fs";
import { Hash } from "@smithy/hash-node";
import { SignatureV4 } from "@smithy/signature-v4";

// The SDK's URI escaping (RFC 3986: encodeURIComponent plus !'()*).
const escapeUri = (text) => encodeURIComponent(text).replace(/[!'()*]/g, (c) => `%${c.charCodeAt(0).toString(16).toUpperCase()}`);

const requests = JSON.parse(readFileSync(process.argv[2], "utf8"));
const headers = [];
for (const request of requests) {
  const signer = new SignatureV4({
    credentials: { accessKeyId: request.access_key, secretAccessKey: request.secret },
    region: request.region,
    service: "s3",
    sha256: Hash.bind(null, "sha256"),
    uriEscapePath: false, // S3: the path is escaped once, as the SDK's S3 client does
  });
  const date = request.amz_date;
  const signingDate = new Date(Date.UTC(+date.slice(0, 4), +date.slice(4, 6) - 1, +date.slice(6, 8), +date.slice(9, 11), +date.slice(11, 13),
                                        +date.slice(13, 15)));
  const signed = await signer.sign({
    method: request.method,
    protocol: "http:",
    hostname: request.headers.host,
    path: request.path.split("/").map(escapeUri).join("/"),
    query: request.query,
    headers: request.headers,
  }, { signingDate });
  headers.push(signed.headers.authorization);
}
console.log(JSON.stringify(headers));
