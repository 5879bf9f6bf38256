// Records a lab can sign (issue 35, docs/signing.md): certificates and test reports signed with the
// lab's Ed25519 key, in an envelope (imucal-signed/1) anyone can verify offline with the lab's
// public key or its fingerprint. libsodium does the cryptography; its header stays in signing.cpp.
//
// What is signed is the canonical form of the content (canonical_json): the envelope may be
// re-indented, or its keys reordered, by any tool in between and still verify, because the
// verifier recomputes the canonical bytes from the parsed content instead of trusting the file's.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <variant>

#include <nlohmann/json.hpp>

namespace imucal::signing {

// Ed25519's sizes (libsodium's crypto_sign_*BYTES; signing.cpp checks that they agree).
inline constexpr std::size_t kPublicKeyBytes = 32;
inline constexpr std::size_t kSecretKeyBytes = 64;  // libsodium's form: the 32-byte seed, then the public key
inline constexpr std::size_t kSignatureBytes = 64;

using PublicKey = std::array<unsigned char, kPublicKeyBytes>;
using SecretKey = std::array<unsigned char, kSecretKeyBytes>;

struct KeyPair {
  PublicKey public_key{};
  SecretKey secret_key{};
};

// The bytes that are hashed and signed: `content.dump()`. nlohmann::json keeps an object's keys in
// a std::map, so they come out sorted by their UTF-8 bytes, with no whitespace, strings in UTF-8
// (only control characters, '"' and '\\' escaped) and a double as the shortest text that parses
// back to the same double. Parsing that text gives the same json value, whose dump is the same
// text again: the form survives a file's write and read, which is what lets a verifier recompute
// it. Throws nlohmann::json::type_error on a string that is not valid UTF-8.
std::string canonical_json(const nlohmann::json& content);

// Lower-case hex SHA-256 of `bytes` (a certificate's content_sha256, the audit trail's links).
std::string sha256_hex(const std::string& bytes);

// A new key pair from the system's random source.
KeyPair generate_key_pair();

// "ed25519:" and the first 16 bytes of the public key's SHA-256 in lower-case hex, in groups of
// four digits: "ed25519:1a2b:3c4d:...": short enough to print on a certificate and to read out.
std::string fingerprint(const PublicKey& public_key);

// A fingerprint as an operator may type it: upper or lower case, with or without "ed25519:" and
// the colons. Returns fingerprint()'s form; throws std::invalid_argument saying what it expects.
std::string parse_fingerprint(const std::string& text);

// Writes the key file `path` (imucal-signing-key/1: format, algorithm, public_key and secret_key in
// base64, fingerprint, created as ISO-8601 UTC), mode 0600, and beside it `path`.pub with the
// public part only (imucal-signing-public-key/1), mode 0644. Never overwrites: throws
// std::runtime_error naming the file when either exists, or when either cannot be written (then
// neither is left behind).
void write_key_file(const std::string& path, const KeyPair& key);

// Reads a key file written by write_key_file. Throws std::runtime_error naming the file and what
// to do: when group or others may read or write it ("chmod 600 FILE"), when it is not JSON, or
// when a key is missing, of the wrong type or wrong (naming the key), or its secret key is not
// the public key's.
KeyPair read_key_file(const std::string& path);

// The public key of a .pub file, or the public part of a key file (its secret part is not read).
// Throws std::runtime_error naming the file and the key that is wrong.
PublicKey read_public_key(const std::string& path);

// The kinds of document a lab signs: sign_document refuses any other.
inline constexpr const char* kCertificate = "certificate";
inline constexpr const char* kTestReport = "test-report";

// The signed envelope (imucal-signed/1) of `content`:
//   {"format": "imucal-signed/1", "kind": kind, "content": content,
//    "content_sha256": hex SHA-256 of canonical_json(content),
//    "signature": {"algorithm": "ed25519", "public_key": base64, "key_fingerprint": fingerprint,
//                  "value": base64 of the detached Ed25519 signature of canonical_json(content)}}
// Throws std::invalid_argument for a kind other than kCertificate or kTestReport, and for content
// holding a NaN or an infinity (JSON has no such number: the canonical form would say null, a
// value the certificate did not state).
nlohmann::json sign_document(const nlohmann::json& content, const std::string& kind, const KeyPair& key);

// Whose key the verifier expects: none (checks 1-3 only), the lab's public key, or its fingerprint
// (fingerprint()'s form; parse_fingerprint makes it from what an operator typed).
struct NoExpectedKey {};
struct ExpectedFingerprint {
  std::string fingerprint;
};
using ExpectedKey = std::variant<NoExpectedKey, PublicKey, ExpectedFingerprint>;

enum class CheckOutcome {
  kPassed,
  kFailed,
  kNotRun,      // an earlier check failed
  kNotChecked,  // the key check, when no expected key was given
};

struct Check {
  const char* name = "";  // "format", "content hash", "signature", "key"
  CheckOutcome outcome = CheckOutcome::kNotRun;
  std::string message;    // what was found, in the operator's words
};

// The four checks of verify_document, in their order. verified() only when all four passed.
struct Verification {
  Check format{"format", CheckOutcome::kNotRun, {}};
  Check content_hash{"content hash", CheckOutcome::kNotRun, {}};
  Check signature{"signature", CheckOutcome::kNotRun, {}};
  Check key{"key", CheckOutcome::kNotRun, {}};
  std::string message;  // one line: verified, not verified and why (the first failure)

  bool verified() const;
  // The first check that failed; nullptr when none did.
  const Check* first_failure() const;
  std::array<const Check*, 4> checks() const { return {&format, &content_hash, &signature, &key}; }
};

// Checks a signed envelope, in this order, stopping at the first failure:
//   1 format: imucal-signed/1, every key present with the right type, nothing unsigned beside them;
//   2 content hash: content_sha256 is the SHA-256 of canonical_json(content) (the content is as it
//     was when the hash was written);
//   3 signature: key_fingerprint is the fingerprint of signature.public_key, and the signature is
//     that key's over canonical_json(content) (no one without the secret key changed anything);
//   4 key: signature.public_key is the lab's (`expected`). With NoExpectedKey it is not checked
//     and the document is not verified: anyone can sign with a key of their own.
// Never throws for a bad document: what is wrong is in the result. Throws std::invalid_argument
// (parse_fingerprint's) when an ExpectedFingerprint is not a fingerprint.
Verification verify_document(const nlohmann::json& envelope, const ExpectedKey& expected);

// verify_document of a document's text (a downloaded file): text that is not JSON fails the
// format check, with the parser's words.
Verification verify_document_text(const std::string& text, const ExpectedKey& expected);

}  // namespace imucal::signing
