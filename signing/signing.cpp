#include "signing/signing.hpp"

#include <fcntl.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <initializer_list>
#include <stdexcept>
#include <utility>

namespace imucal::signing {

static_assert(kPublicKeyBytes == crypto_sign_PUBLICKEYBYTES);
static_assert(kSecretKeyBytes == crypto_sign_SECRETKEYBYTES);
static_assert(kSignatureBytes == crypto_sign_BYTES);

namespace {

using nlohmann::json;

constexpr const char* kEnvelopeFormat = "imucal-signed/1";
constexpr const char* kKeyFormat = "imucal-signing-key/1";
constexpr const char* kPublicKeyFormat = "imucal-signing-public-key/1";
constexpr const char* kAlgorithm = "ed25519";
constexpr std::size_t kFingerprintBytes = 16;  // of the SHA-256: 128 bits, 32 hex digits

using Sha256 = std::array<unsigned char, crypto_hash_sha256_BYTES>;
using Signature = std::array<unsigned char, kSignatureBytes>;

void init_sodium() {
  // sodium_init is thread-safe and may be called again; the static runs it once all the same.
  // It fails only when the system has no random source.
  static const bool ready = sodium_init() >= 0;
  if (!ready) throw std::runtime_error("libsodium cannot start (no random source)");
}

std::string to_base64(const unsigned char* bytes, std::size_t count) {
  const std::size_t size = sodium_base64_encoded_len(count, sodium_base64_VARIANT_ORIGINAL);  // with the NUL
  std::string text(size, '\0');
  sodium_bin2base64(text.data(), size, bytes, count, sodium_base64_VARIANT_ORIGINAL);
  text.resize(size - 1);
  return text;
}

// True when `text` is the base64 (padded, no spaces) of exactly `count` bytes, written to `out`.
bool from_base64(const std::string& text, unsigned char* out, std::size_t count) {
  std::size_t decoded = 0;
  const char* end = nullptr;
  const int status = sodium_base642bin(out, count, text.data(), text.size(), nullptr, &decoded, &end,
                                       sodium_base64_VARIANT_ORIGINAL);
  return status == 0 && decoded == count && end == text.data() + text.size();
}

std::string to_hex(const unsigned char* bytes, std::size_t count) {
  std::string text(2 * count + 1, '\0');
  sodium_bin2hex(text.data(), text.size(), bytes, count);
  text.resize(2 * count);
  return text;
}

Sha256 sha256(const std::string& text) {
  Sha256 digest{};
  crypto_hash_sha256(digest.data(), reinterpret_cast<const unsigned char*>(text.data()), text.size());
  return digest;
}

}  // namespace

std::string sha256_hex(const std::string& bytes) {
  const Sha256 digest = sha256(bytes);
  return to_hex(digest.data(), digest.size());
}

namespace {

std::string iso8601_utc_now() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text;
}

std::string mode_text(mode_t mode) {
  char text[8];
  std::snprintf(text, sizeof text, "%04o", static_cast<unsigned>(mode & 07777));
  return text;
}

// Creates `path` with `mode`, never over an existing file, and writes `text` to disk (fsync): a
// key announced as written is on the disk. Throws naming the file; leaves nothing behind then.
void create_file(const std::string& path, const std::string& text, mode_t mode) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, mode);
  if (fd < 0) {
    if (errno == EEXIST)
      throw std::runtime_error(path + " already exists: a key file is never overwritten (move it away first, or "
                                      "write the new key elsewhere)");
    throw std::runtime_error("cannot create " + path + ": " + std::strerror(errno));
  }
  // The umask may only take bits away from open's mode: the public key is made readable by all.
  bool ok = ::fchmod(fd, mode) == 0;
  int error = ok ? 0 : errno;
  for (std::size_t written = 0; ok && written < text.size();) {
    const ssize_t n = ::write(fd, text.data() + written, text.size() - written);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      ok = false;
      error = errno;
    } else {
      written += static_cast<std::size_t>(n);
    }
  }
  if (ok && ::fsync(fd) != 0) {
    ok = false;
    error = errno;
  }
  if (::close(fd) != 0 && ok) {
    ok = false;
    error = errno;
  }
  if (!ok) {
    ::unlink(path.c_str());
    throw std::runtime_error("cannot write " + path + ": " + std::strerror(error));
  }
}

// The text of `path` and its mode, read through one descriptor (the mode is the file's read).
std::string read_file(const std::string& path, mode_t& mode) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error("cannot read " + path + ": " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throw std::runtime_error("cannot read " + path + ": not a regular file");
  }
  mode = st.st_mode;
  std::string text;
  char buffer[4096];
  for (;;) {
    const ssize_t n = ::read(fd, buffer, sizeof buffer);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int error = errno;
      ::close(fd);
      throw std::runtime_error("cannot read " + path + ": " + std::strerror(error));
    }
    if (n == 0) break;
    text.append(buffer, static_cast<std::size_t>(n));
  }
  ::close(fd);
  return text;
}

json parse_file(const std::string& path, const std::string& text) {
  try {
    json j = json::parse(text);
    if (!j.is_object()) throw std::runtime_error(path + " is not a key file: its JSON is not an object");
    return j;
  } catch (const json::exception& e) {
    throw std::runtime_error(path + " is not a key file: it is not JSON (" + e.what() + ")");
  }
}

// The keys a key file may hold (`_` keys are comments, as everywhere in imucal); any other is named.
void refuse_unknown_keys(const json& j, std::initializer_list<const char*> known, const std::string& where) {
  for (const auto& item : j.items()) {
    const std::string& key = item.key();
    if (key.rfind('_', 0) == 0) continue;
    bool found = false;
    for (const char* k : known) found = found || key == k;
    if (!found) throw std::runtime_error(where + ": unknown key '" + key + "'");
  }
}

std::string string_at(const json& j, const char* key, const std::string& where) {
  const auto it = j.find(key);
  if (it == j.end()) throw std::runtime_error(where + ": the key '" + std::string(key) + "' is missing");
  if (!it->is_string()) throw std::runtime_error(where + ": '" + std::string(key) + "' must be a string");
  return it->get<std::string>();
}

PublicKey public_key_at(const json& j, const std::string& where) {
  if (const std::string algorithm = string_at(j, "algorithm", where); algorithm != kAlgorithm)
    throw std::runtime_error(where + ": 'algorithm' is '" + algorithm + "'; imucal signs with ed25519 only");
  PublicKey key{};
  if (!from_base64(string_at(j, "public_key", where), key.data(), key.size()))
    throw std::runtime_error(where + ": 'public_key' is not the base64 of a " + std::to_string(kPublicKeyBytes) +
                             "-byte Ed25519 public key");
  // The fingerprint is what a person compares: one that is not the key's would mislead them.
  if (const std::string stated = string_at(j, "fingerprint", where); stated != fingerprint(key))
    throw std::runtime_error(where + ": 'fingerprint' " + stated + " is not that of public_key (" + fingerprint(key) +
                             ")");
  string_at(j, "created", where);
  return key;
}

// Where in `j` (named from `path`) a number is NaN or infinite; empty when none is.
std::string non_finite_number(const json& j, const std::string& path) {
  if (j.is_number_float() && !std::isfinite(j.get<double>())) return path;
  if (j.is_object()) {
    for (const auto& item : j.items())
      if (std::string at = non_finite_number(item.value(), path + "." + item.key()); !at.empty()) return at;
  } else if (j.is_array()) {
    for (std::size_t i = 0; i < j.size(); ++i)
      if (std::string at = non_finite_number(j[i], path + "[" + std::to_string(i) + "]"); !at.empty()) return at;
  }
  return {};
}

bool is_hex(const std::string& text) {
  for (const char c : text)
    if (std::isxdigit(static_cast<unsigned char>(c)) == 0) return false;
  return true;
}

std::string lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

// What the format check reads from an envelope.
struct Envelope {
  const json* content = nullptr;
  std::string kind;
  std::string content_sha256;  // lower-case hex
  PublicKey public_key{};
  std::string key_fingerprint;
  Signature signature{};
};

// The reason the envelope's `signature` object `s` is not well formed; empty when it is.
std::string read_signature(const json& s, Envelope& out) {
  if (!s.is_object()) return "'signature' must be an object";
  for (const auto& item : s.items())
    if (item.key() != "algorithm" && item.key() != "public_key" && item.key() != "key_fingerprint" &&
        item.key() != "value")
      return "'signature." + item.key() + "' is not a key of imucal-signed/1";
  for (const char* key : {"algorithm", "public_key", "key_fingerprint", "value"}) {
    if (!s.contains(key)) return "'signature." + std::string(key) + "' is missing";
    if (!s.at(key).is_string()) return "'signature." + std::string(key) + "' must be a string";
  }
  if (const auto algorithm = s.at("algorithm").get<std::string>(); algorithm != kAlgorithm)
    return "'signature.algorithm' is '" + algorithm + "'; only ed25519 signatures are verified";
  if (!from_base64(s.at("public_key").get<std::string>(), out.public_key.data(), out.public_key.size()))
    return "'signature.public_key' is not the base64 of a 32-byte Ed25519 public key";
  if (!from_base64(s.at("value").get<std::string>(), out.signature.data(), out.signature.size()))
    return "'signature.value' is not the base64 of a 64-byte Ed25519 signature";
  out.key_fingerprint = s.at("key_fingerprint").get<std::string>();
  return {};
}

// The reason `e` is not a well-formed imucal-signed/1 envelope; empty when it is (`out` filled).
std::string read_envelope(const json& e, Envelope& out) {
  if (!e.is_object()) return "the document is not a JSON object, so not a signed imucal document";
  if (!e.contains("format")) return "'format' is missing: not a signed imucal document (imucal-signed/1)";
  if (!e.at("format").is_string() || e.at("format").get<std::string>() != kEnvelopeFormat)
    return "'format' is " + e.at("format").dump() + ", not \"imucal-signed/1\": not a signed imucal document";
  // Everything beside the content is outside the signature: a document carrying more than the
  // format's keys could carry unsigned claims a reader mistakes for signed ones.
  for (const auto& item : e.items())
    if (item.key() != "format" && item.key() != "kind" && item.key() != "content" && item.key() != "content_sha256" &&
        item.key() != "signature")
      return "'" + item.key() + "' is not a key of imucal-signed/1 (it would not be covered by the signature)";
  for (const char* key : {"kind", "content", "content_sha256", "signature"})
    if (!e.contains(key)) return "'" + std::string(key) + "' is missing";
  if (!e.at("kind").is_string()) return "'kind' must be a string";
  out.kind = e.at("kind").get<std::string>();
  if (out.kind != kCertificate && out.kind != kTestReport)
    return "'kind' is '" + out.kind + "', neither certificate nor test-report";
  if (!e.at("content").is_object()) return "'content' must be an object";
  out.content = &e.at("content");
  const json& hash = e.at("content_sha256");
  if (!hash.is_string() || hash.get<std::string>().size() != 2 * crypto_hash_sha256_BYTES ||
      !is_hex(hash.get<std::string>()))
    return "'content_sha256' must be a SHA-256 in hex (64 digits)";
  out.content_sha256 = lower(hash.get<std::string>());
  return read_signature(e.at("signature"), out);
}

bool key_matches(const PublicKey& key, const ExpectedKey& expected, std::string& lab) {
  if (const auto* lab_key = std::get_if<PublicKey>(&expected)) {
    lab = fingerprint(*lab_key);
    return sodium_memcmp(key.data(), lab_key->data(), key.size()) == 0;
  }
  if (const auto* lab_fingerprint = std::get_if<ExpectedFingerprint>(&expected)) {
    lab = lab_fingerprint->fingerprint;
    return parse_fingerprint(lab) == fingerprint(key);
  }
  return false;
}

void pass(Check& c, std::string message) {
  c.outcome = CheckOutcome::kPassed;
  c.message = std::move(message);
}

// Marks `failed` and the checks after it; the result's message names the first failure.
Verification& fail(Verification& v, Check& failed, std::string message) {
  failed.outcome = CheckOutcome::kFailed;
  failed.message = std::move(message);
  bool after = false;
  for (Check* c : {&v.format, &v.content_hash, &v.signature, &v.key}) {
    if (after) c->message = std::string("the ") + failed.name + " check failed";
    after = after || c == &failed;
  }
  v.message = std::string("NOT VERIFIED: the ") + failed.name + " check failed: " + failed.message;
  return v;
}

}  // namespace

std::string canonical_json(const nlohmann::json& content) { return content.dump(); }

KeyPair generate_key_pair() {
  init_sodium();
  KeyPair key;
  crypto_sign_keypair(key.public_key.data(), key.secret_key.data());
  return key;
}

std::string fingerprint(const PublicKey& public_key) {
  init_sodium();
  Sha256 digest{};
  crypto_hash_sha256(digest.data(), public_key.data(), public_key.size());
  const std::string hex = to_hex(digest.data(), kFingerprintBytes);
  std::string text = kAlgorithm;
  for (std::size_t i = 0; i < hex.size(); i += 4) text += ":" + hex.substr(i, 4);
  return text;
}

std::string parse_fingerprint(const std::string& text) {
  std::string digits = lower(text);
  const auto first = digits.find_first_not_of(" \t");
  digits = first == std::string::npos ? "" : digits.substr(first, digits.find_last_not_of(" \t") - first + 1);
  if (digits.rfind("ed25519:", 0) == 0) digits.erase(0, 8);
  std::string hex;
  for (const char c : digits)
    if (c != ':') hex += c;
  if (hex.size() != 2 * kFingerprintBytes || !is_hex(hex))
    throw std::invalid_argument("'" + text + "' is not a key fingerprint: expected ed25519: and 32 hex digits in "
                                "groups of four (ed25519:1a2b:3c4d:...:7e8f), as imucal keygen prints it");
  std::string canonical = kAlgorithm;
  for (std::size_t i = 0; i < hex.size(); i += 4) canonical += ":" + hex.substr(i, 4);
  return canonical;
}

void write_key_file(const std::string& path, const KeyPair& key) {
  init_sodium();
  const std::string created = iso8601_utc_now();
  const std::string fp = fingerprint(key.public_key);
  const std::string public_b64 = to_base64(key.public_key.data(), key.public_key.size());
  // ordered_json: the format first, so that a person opening the file sees what it is.
  nlohmann::ordered_json secret;
  secret["format"] = kKeyFormat;
  secret["algorithm"] = kAlgorithm;
  secret["public_key"] = public_b64;
  secret["secret_key"] = to_base64(key.secret_key.data(), key.secret_key.size());
  secret["fingerprint"] = fp;
  secret["created"] = created;
  nlohmann::ordered_json pub;
  pub["format"] = kPublicKeyFormat;
  pub["algorithm"] = kAlgorithm;
  pub["public_key"] = public_b64;
  pub["fingerprint"] = fp;
  pub["created"] = created;
  std::string secret_text = secret.dump(2) + "\n";
  create_file(path, secret_text, 0600);
  sodium_memzero(secret_text.data(), secret_text.size());
  try {
    create_file(path + ".pub", pub.dump(2) + "\n", 0644);
  } catch (...) {
    // A key without its public half is one nobody could verify: neither is left.
    ::unlink(path.c_str());
    throw;
  }
}

KeyPair read_key_file(const std::string& path) {
  init_sodium();
  mode_t mode = 0;
  std::string text = read_file(path, mode);
  if ((mode & 077) != 0) {
    sodium_memzero(text.data(), text.size());
    throw std::runtime_error("the signing key " + path + " may be read or changed by group or others (mode " +
                             mode_text(mode) + "), so it is not used: `chmod 600 " + path +
                             "` if no one else could have copied it, else make a new key (imucal keygen)");
  }
  const json j = parse_file(path, text);
  sodium_memzero(text.data(), text.size());
  if (const std::string format = string_at(j, "format", path); format != kKeyFormat) {
    const std::string hint = format == kPublicKeyFormat ? " (a public key: the signing key is the file without .pub)" : "";
    throw std::runtime_error(path + ": 'format' is '" + format + "', not " + kKeyFormat + hint);
  }
  refuse_unknown_keys(j, {"format", "algorithm", "public_key", "secret_key", "fingerprint", "created"}, path);
  KeyPair key;
  key.public_key = public_key_at(j, path);
  if (!from_base64(string_at(j, "secret_key", path), key.secret_key.data(), key.secret_key.size()))
    throw std::runtime_error(path + ": 'secret_key' is not the base64 of a " + std::to_string(kSecretKeyBytes) +
                             "-byte Ed25519 secret key");
  // The secret key is the seed and the public key: both are derived again from the seed, so a
  // secret key from one file pasted beside the public key of another is caught here, not by
  // every signature failing later.
  unsigned char seed[crypto_sign_SEEDBYTES];
  crypto_sign_ed25519_sk_to_seed(seed, key.secret_key.data());
  KeyPair derived;
  crypto_sign_seed_keypair(derived.public_key.data(), derived.secret_key.data(), seed);
  sodium_memzero(seed, sizeof seed);
  const bool consistent = sodium_memcmp(derived.secret_key.data(), key.secret_key.data(), kSecretKeyBytes) == 0 &&
                          sodium_memcmp(derived.public_key.data(), key.public_key.data(), kPublicKeyBytes) == 0;
  sodium_memzero(derived.secret_key.data(), derived.secret_key.size());
  if (!consistent) throw std::runtime_error(path + ": 'secret_key' does not belong to 'public_key'");
  return key;
}

PublicKey read_public_key(const std::string& path) {
  init_sodium();
  mode_t mode = 0;
  std::string text = read_file(path, mode);
  const json j = parse_file(path, text);
  sodium_memzero(text.data(), text.size());  // it may be a key file
  const std::string format = string_at(j, "format", path);
  if (format == kPublicKeyFormat) {
    refuse_unknown_keys(j, {"format", "algorithm", "public_key", "fingerprint", "created"}, path);
  } else if (format != kKeyFormat) {
    throw std::runtime_error(path + ": 'format' is '" + format + "', neither a public key (" + kPublicKeyFormat +
                             ") nor a key file (" + kKeyFormat + ")");
  }
  return public_key_at(j, path);
}

nlohmann::json sign_document(const nlohmann::json& content, const std::string& kind, const KeyPair& key) {
  init_sodium();
  if (kind != kCertificate && kind != kTestReport)
    throw std::invalid_argument("cannot sign a document of kind '" + kind + "': only certificate and test-report");
  if (!content.is_object()) throw std::invalid_argument("cannot sign: the content must be a JSON object");
  if (const std::string at = non_finite_number(content, "content"); !at.empty())
    throw std::invalid_argument("cannot sign: " + at + " is not a finite number (JSON would write it as null)");
  if (sodium_memcmp(key.secret_key.data() + crypto_sign_SEEDBYTES, key.public_key.data(), kPublicKeyBytes) != 0)
    throw std::invalid_argument("cannot sign: the key pair's secret key is not its public key's");
  const std::string bytes = canonical_json(content);
  const Sha256 digest = sha256(bytes);
  Signature signature{};
  crypto_sign_detached(signature.data(), nullptr, reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(),
                       key.secret_key.data());
  return {{"format", kEnvelopeFormat},
          {"kind", kind},
          {"content", content},
          {"content_sha256", to_hex(digest.data(), digest.size())},
          {"signature",
           {{"algorithm", kAlgorithm},
            {"public_key", to_base64(key.public_key.data(), key.public_key.size())},
            {"key_fingerprint", fingerprint(key.public_key)},
            {"value", to_base64(signature.data(), signature.size())}}}};
}

bool Verification::verified() const {
  for (const Check* c : checks())
    if (c->outcome != CheckOutcome::kPassed) return false;
  return true;
}

const Check* Verification::first_failure() const {
  for (const Check* c : checks())
    if (c->outcome == CheckOutcome::kFailed) return c;
  return nullptr;
}

Verification verify_document(const nlohmann::json& envelope, const ExpectedKey& expected) {
  init_sodium();
  // The caller's mistake, not the document's: said before any check.
  if (const auto* lab = std::get_if<ExpectedFingerprint>(&expected)) parse_fingerprint(lab->fingerprint);
  Verification v;
  // 1: the format, and what the other checks need from it.
  Envelope e;
  if (std::string problem = read_envelope(envelope, e); !problem.empty()) return fail(v, v.format, std::move(problem));
  pass(v.format, std::string(kEnvelopeFormat) + ", a " + e.kind);

  // 2: the content as it is now, against the hash written when it was signed.
  const std::string bytes = canonical_json(*e.content);
  const Sha256 digest = sha256(bytes);
  const std::string actual = to_hex(digest.data(), digest.size());
  if (actual != e.content_sha256)
    return fail(v, v.content_hash,
                "the content's SHA-256 is " + actual + " but the document states " + e.content_sha256 +
                    ": the content was changed after it was signed (or the file is damaged)");
  pass(v.content_hash, "SHA-256 " + actual);

  // 3: the signature, with the key the envelope names (whose it is, is check 4).
  const std::string signer = fingerprint(e.public_key);
  if (lower(e.key_fingerprint) != signer)
    return fail(v, v.signature,
                "'signature.key_fingerprint' is " + e.key_fingerprint + " but the document's public key is " + signer +
                    ": the key or its fingerprint was changed after signing");
  if (crypto_sign_verify_detached(e.signature.data(), reinterpret_cast<const unsigned char*>(bytes.data()),
                                  bytes.size(), e.public_key.data()) != 0)
    return fail(v, v.signature,
                "the signature is not key " + signer +
                    "'s over this content: the content (and its hash) was changed after signing, or the signature "
                    "is damaged");
  pass(v.signature, "a valid Ed25519 signature by key " + signer);

  // 4: whose key. Anyone can make a key and sign; only the lab's key says the lab issued it.
  if (std::holds_alternative<NoExpectedKey>(expected)) {
    v.key.outcome = CheckOutcome::kNotChecked;
    v.key.message = "not checked: no lab key was given (--key LAB.pub or --fingerprint FP); the document is intact "
                    "and signed by key " + signer + ", but anyone can sign with a key of their own";
    v.message = "NOT VERIFIED: intact and signed by key " + signer + ", but the key was not checked against the lab's";
    return v;
  }
  std::string lab;
  if (!key_matches(e.public_key, expected, lab))
    return fail(v, v.key,
                "signed by key " + signer + ", not by the lab's key " + lab +
                    ": someone else signed it, or the lab key given is not the one the lab signs with");
  pass(v.key, "the lab's key " + signer);
  v.message = "VERIFIED: a " + e.kind + " signed by the lab's key " + signer + ", unchanged since";
  return v;
}

Verification verify_document_text(const std::string& text, const ExpectedKey& expected) {
  json envelope;
  try {
    envelope = json::parse(text);
  } catch (const json::exception& e) {
    if (const auto* lab = std::get_if<ExpectedFingerprint>(&expected)) parse_fingerprint(lab->fingerprint);
    Verification v;
    return fail(v, v.format, std::string("the file is not JSON (") + e.what() + ")");
  }
  return verify_document(envelope, expected);
}

}  // namespace imucal::signing
