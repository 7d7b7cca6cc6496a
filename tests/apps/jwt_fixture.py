#!/usr/bin/env python3
"""Test fixture for `serve --jwks`: an RSA key (openssl CLI), its JWKS and RS256 tokens.

    jwt_fixture.py DIR   writes DIR/key.pem, DIR/jwks.json and DIR/<name>.jwt for the tokens
                         below (issuer https://login.example.com/, audience hanzo-fusion).
"""
import base64
import json
import subprocess
import sys
import time
from pathlib import Path


def b64url(data: bytes) -> str:
    return base64.urlsafe_b64encode(data).rstrip(b"=").decode()


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    key = out / "key.pem"
    subprocess.run(["openssl", "genrsa", "-out", str(key), "2048"], check=True, capture_output=True)
    modulus = subprocess.run(["openssl", "rsa", "-in", str(key), "-noout", "-modulus"], check=True, capture_output=True, text=True)
    n = bytes.fromhex(modulus.stdout.strip().split("=", 1)[1])
    jwks = {"keys": [{"kty": "RSA", "kid": "test-key", "use": "sig", "alg": "RS256", "n": b64url(n), "e": b64url((65537).to_bytes(3, "big"))}]}
    (out / "jwks.json").write_text(json.dumps(jwks))
    now = int(time.time())
    base = {"iss": "https://login.example.com/", "aud": "hanzo-fusion", "sub": "robot-7", "org": "acme", "iat": now - 5, "exp": now + 3600}
    tokens = {
        "valid": dict(base, scope="fusion:session:read fusion:session:write"),
        "expired": dict(base, scope="fusion:session:read", exp=now - 3600),
        "no_scope": dict(base, scope="openid profile"),
        "wrong_audience": dict(base, aud="another-service", scope="fusion:session:read"),
        # every fusion scope, of two organizations
        "acme_operator": dict(base, scope="fusion:session:read fusion:session:write fusion:map:read fusion:map:write"),
        "globex_operator": dict(base, sub="robot-9", org="globex",
                                scope="fusion:session:read fusion:session:write fusion:map:read fusion:map:write"),
    }
    header = b64url(json.dumps({"alg": "RS256", "typ": "JWT", "kid": "test-key"}).encode())
    for name, claims in tokens.items():
        signing_input = f"{header}.{b64url(json.dumps(claims).encode())}"
        signature = subprocess.run(["openssl", "dgst", "-sha256", "-sign", str(key)], input=signing_input.encode(), check=True,
                                   capture_output=True).stdout
        (out / f"{name}.jwt").write_text(f"{signing_input}.{b64url(signature)}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
