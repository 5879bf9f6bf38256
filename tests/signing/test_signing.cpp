// Records a lab can sign (docs/signing.md): a signed document verifies; each kind of tampering
// fails the check that names it; key files are private and never overwritten; the canonical form
// survives a file's write and read.
#include <sys/stat.h>

#include <cctype>
#include <filesystem>
#include <fstream>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "signing/signing.hpp"
#include "tests/test_paths.hpp"

namespace fs = std::filesystem;
using nlohmann::json;
using namespace imucal::signing;

namespace {

// A certificate's content as the daemon writes one (the numbers are what a tamperer would change).
json certificate() {
  return json::parse(R"({
    "number": "LAB-2026-000042", "unit": {"part_number": "NAV-100", "serial": "IMU-0042"},
    "issued": "2026-11-27T12:00:00Z",
    "results": {"gyro": {"bias_dph": [0.0123, -0.0071, 0.0042], "scale_ppm": [12.5, -3.25, 7.0]},
                "accel": {"bias_ug": [41.5, -12.0, 8.75]}},
    "verdict": "pass", "operator": "Zoë Müller"})");
}

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::path(imucaltest::test_tmp_dir()) / name;
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

// The envelope written to a file and read back, as a downloaded document is.
json through_text(const json& envelope) { return json::parse(envelope.dump(2)); }

std::string replace_once(std::string text, const std::string& from, const std::string& to) {
  const auto at = text.find(from);
  if (at == std::string::npos) throw std::logic_error("replace_once: '" + from + "' is not in the text");
  return text.replace(at, from.size(), to);
}

mode_t mode_of(const fs::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw std::runtime_error("cannot stat " + path.string());
  return st.st_mode & 07777;
}

void expect_failed_at(const Verification& v, const Check& expected, const std::string& words) {
  const Check* failed = v.first_failure();
  ASSERT_NE(failed, nullptr) << v.message;
  EXPECT_EQ(failed, &expected) << v.message;
  EXPECT_EQ(expected.outcome, CheckOutcome::kFailed);
  EXPECT_FALSE(v.verified());
  EXPECT_NE(expected.message.find(words), std::string::npos) << expected.message;
  EXPECT_NE(v.message.find(std::string("the ") + expected.name + " check failed"), std::string::npos) << v.message;
  // The checks after the failed one did not run.
  bool after = false;
  for (const Check* c : v.checks()) {
    if (after) {
      EXPECT_EQ(c->outcome, CheckOutcome::kNotRun) << c->name;
    }
    after = after || c == &expected;
  }
}

}  // namespace

TEST(Signing, ASignedDocumentVerifiesWithTheLabsKeyOrItsFingerprint) {
  const KeyPair lab = generate_key_pair();
  const json envelope = sign_document(certificate(), kCertificate, lab);
  EXPECT_EQ(envelope.at("format"), "imucal-signed/1");
  EXPECT_EQ(envelope.at("kind"), "certificate");
  EXPECT_EQ(envelope.at("content"), certificate());
  EXPECT_EQ(envelope.at("content_sha256").get<std::string>().size(), 64u);
  EXPECT_EQ(envelope.at("signature").at("algorithm"), "ed25519");
  EXPECT_EQ(envelope.at("signature").at("key_fingerprint"), fingerprint(lab.public_key));

  for (const ExpectedKey& expected :
       {ExpectedKey{lab.public_key}, ExpectedKey{ExpectedFingerprint{fingerprint(lab.public_key)}}}) {
    const Verification v = verify_document(through_text(envelope), expected);
    EXPECT_TRUE(v.verified()) << v.message;
    EXPECT_EQ(v.first_failure(), nullptr);
    for (const Check* c : v.checks()) EXPECT_EQ(c->outcome, CheckOutcome::kPassed) << c->name << ": " << c->message;
    EXPECT_NE(v.message.find("VERIFIED"), std::string::npos) << v.message;
  }
  // Re-indented, keys reordered by another tool: the same content, so it still verifies.
  const Verification compact = verify_document_text(envelope.dump(), lab.public_key);
  EXPECT_TRUE(compact.verified()) << compact.message;
  EXPECT_TRUE(verify_document(sign_document(certificate(), kTestReport, lab), lab.public_key).verified());
}

TEST(Signing, WithoutAnExpectedKeyTheKeyIsNotCheckedAndTheDocumentNotVerified) {
  const KeyPair lab = generate_key_pair();
  const Verification v = verify_document(sign_document(certificate(), kCertificate, lab), NoExpectedKey{});
  EXPECT_EQ(v.format.outcome, CheckOutcome::kPassed);
  EXPECT_EQ(v.content_hash.outcome, CheckOutcome::kPassed);
  EXPECT_EQ(v.signature.outcome, CheckOutcome::kPassed);
  EXPECT_EQ(v.key.outcome, CheckOutcome::kNotChecked);
  EXPECT_EQ(v.first_failure(), nullptr);
  EXPECT_FALSE(v.verified());
  EXPECT_NE(v.key.message.find("not checked"), std::string::npos) << v.key.message;
  EXPECT_NE(v.message.find("NOT VERIFIED"), std::string::npos) << v.message;
}

TEST(Signing, AChangedDigitInTheContentFailsTheContentHashCheck) {
  const KeyPair lab = generate_key_pair();
  const std::string text = sign_document(certificate(), kCertificate, lab).dump(2);
  const std::string tampered = replace_once(text, "0.0123", "0.0124");
  const Verification v = verify_document_text(tampered, lab.public_key);
  expect_failed_at(v, v.content_hash, "changed after it was signed");
  EXPECT_EQ(v.format.outcome, CheckOutcome::kPassed);
}

TEST(Signing, AChangedSignatureFailsTheSignatureCheck) {
  const KeyPair lab = generate_key_pair();
  json envelope = sign_document(certificate(), kCertificate, lab);
  std::string value = envelope["signature"]["value"].get<std::string>();
  value[10] = value[10] == 'A' ? 'B' : 'A';
  envelope["signature"]["value"] = value;
  const Verification v = verify_document(through_text(envelope), lab.public_key);
  expect_failed_at(v, v.signature, "the signature is not key");
  EXPECT_EQ(v.content_hash.outcome, CheckOutcome::kPassed);
}

// The hash is no protection of its own: anyone can recompute it. The signature is.
TEST(Signing, AContentWhoseHashWasRecomputedAfterTamperingStillFailsTheSignature) {
  const KeyPair lab = generate_key_pair();
  json envelope = sign_document(certificate(), kCertificate, lab);
  envelope["content"]["verdict"] = "pass";
  envelope["content"]["results"]["gyro"]["bias_dph"][0] = 0.0012;
  // The SHA-256 of the new content, as a tamperer computes it: the hex digest of a document signed
  // by any key over the same content.
  envelope["content_sha256"] = sign_document(envelope["content"], kCertificate, generate_key_pair())["content_sha256"];
  const Verification v = verify_document(through_text(envelope), lab.public_key);
  expect_failed_at(v, v.signature, "changed after signing");
  EXPECT_EQ(v.content_hash.outcome, CheckOutcome::kPassed);
}

// A forger signs with a key of their own, and puts their key and fingerprint in the envelope:
// checks 1-3 pass, the key check does not.
TEST(Signing, TheSameContentSignedByAnotherKeyFailsTheKeyCheck) {
  const KeyPair lab = generate_key_pair();
  const KeyPair other = generate_key_pair();
  const json forged = through_text(sign_document(certificate(), kCertificate, other));
  for (const ExpectedKey& expected :
       {ExpectedKey{lab.public_key}, ExpectedKey{ExpectedFingerprint{fingerprint(lab.public_key)}}}) {
    const Verification v = verify_document(forged, expected);
    expect_failed_at(v, v.key, "not by the lab's key " + fingerprint(lab.public_key));
    EXPECT_EQ(v.signature.outcome, CheckOutcome::kPassed);
    EXPECT_NE(v.key.message.find(fingerprint(other.public_key)), std::string::npos) << v.key.message;
  }
  // The lab's public key with the forger's signature: the signature check.
  json swapped = forged;
  swapped["signature"]["public_key"] = sign_document(certificate(), kCertificate, lab)["signature"]["public_key"];
  swapped["signature"]["key_fingerprint"] = fingerprint(lab.public_key);
  const Verification v = verify_document(swapped, lab.public_key);
  expect_failed_at(v, v.signature, "the signature is not key");
  // A key_fingerprint that is not the envelope's key's.
  json mislabelled = forged;
  mislabelled["signature"]["key_fingerprint"] = fingerprint(lab.public_key);
  const Verification m = verify_document(mislabelled, lab.public_key);
  expect_failed_at(m, m.signature, "key_fingerprint");
}

TEST(Signing, AMalformedEnvelopeFailsTheFormatCheckNamingWhatIsWrong) {
  const KeyPair lab = generate_key_pair();
  const json good = sign_document(certificate(), kCertificate, lab);
  struct Case {
    const char* what;
    json envelope;
    const char* words;
  };
  json no_format = good;
  no_format.erase("format");
  json other_format = good;
  other_format["format"] = "imucal-signed/2";
  json bad_kind = good;
  bad_kind["kind"] = "invoice";
  json no_content = good;
  no_content.erase("content");
  json short_hash = good;
  short_hash["content_sha256"] = "abc";
  json short_key = good;
  short_key["signature"]["public_key"] = "AAAA";
  json number_signature = good;
  number_signature["signature"]["value"] = 42;
  json unsigned_claim = good;
  unsigned_claim["approved_by"] = "the director";
  for (const Case& c : {Case{"no format", no_format, "'format' is missing"},
                        Case{"other format", other_format, "not \"imucal-signed/1\""},
                        Case{"kind", bad_kind, "'kind' is 'invoice'"},
                        Case{"no content", no_content, "'content' is missing"},
                        Case{"hash", short_hash, "'content_sha256'"},
                        Case{"key", short_key, "'signature.public_key'"},
                        Case{"signature type", number_signature, "'signature.value' must be a string"},
                        Case{"unsigned key", unsigned_claim, "'approved_by' is not a key of imucal-signed/1"},
                        Case{"array", json::array({good}), "not a JSON object"}}) {
    const Verification v = verify_document(c.envelope, lab.public_key);
    SCOPED_TRACE(c.what);
    expect_failed_at(v, v.format, c.words);
  }
  const Verification text = verify_document_text("{\"format\": \"imucal-signed/1\",", lab.public_key);
  expect_failed_at(text, text.format, "not JSON");
  EXPECT_THROW(verify_document(good, ExpectedFingerprint{"ed25519:12"}), std::invalid_argument);
}

TEST(Signing, SignRefusesOtherKindsAndNumbersJsonCannotWrite) {
  const KeyPair lab = generate_key_pair();
  EXPECT_THROW(sign_document(certificate(), "invoice", lab), std::invalid_argument);
  json nan = certificate();
  nan["results"]["gyro"]["bias_dph"][1] = std::numeric_limits<double>::quiet_NaN();
  try {
    sign_document(nan, kCertificate, lab);
    ADD_FAILURE() << "a NaN was signed";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("content.results.gyro.bias_dph[1]"), std::string::npos) << e.what();
  }
  KeyPair mixed = lab;
  mixed.public_key = generate_key_pair().public_key;
  EXPECT_THROW(sign_document(certificate(), kCertificate, mixed), std::invalid_argument);
}

TEST(Signing, TheFingerprintIsShortAndReadAsAnOperatorTypesIt) {
  const KeyPair lab = generate_key_pair();
  const std::string fp = fingerprint(lab.public_key);
  ASSERT_EQ(fp.size(), std::string("ed25519:").size() + 8 * 4 + 7) << fp;
  EXPECT_EQ(fp.rfind("ed25519:", 0), 0u) << fp;
  for (std::size_t i = 12; i < fp.size(); i += 5) EXPECT_EQ(fp[i], ':') << fp;
  EXPECT_EQ(parse_fingerprint(fp), fp);
  std::string upper = fp.substr(8);
  for (char& ch : upper) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
  EXPECT_EQ(parse_fingerprint("  ED25519:" + upper + " "), fp);
  std::string bare;
  for (const char ch : fp.substr(8))
    if (ch != ':') bare += ch;
  EXPECT_EQ(parse_fingerprint(bare), fp);
  EXPECT_THROW(parse_fingerprint("ed25519:1234"), std::invalid_argument);
  EXPECT_THROW(parse_fingerprint(fp.substr(0, fp.size() - 1) + "g"), std::invalid_argument);
  EXPECT_NE(fingerprint(generate_key_pair().public_key), fp);
}

TEST(SigningKeyFile, WrittenPrivateWithItsPublicKeyBesideAndReadBack) {
  const fs::path d = fresh_dir("signing-keyfile");
  const std::string path = (d / "lab.key").string();
  const KeyPair lab = generate_key_pair();
  write_key_file(path, lab);
  EXPECT_EQ(mode_of(path), 0600u);
  EXPECT_EQ(mode_of(path + ".pub"), 0644u);
  const json file = json::parse(std::ifstream(path));
  EXPECT_EQ(file.at("format"), "imucal-signing-key/1");
  EXPECT_EQ(file.at("algorithm"), "ed25519");
  EXPECT_EQ(file.at("fingerprint"), fingerprint(lab.public_key));
  EXPECT_EQ(file.at("created").get<std::string>().back(), 'Z');
  const json pub = json::parse(std::ifstream(path + ".pub"));
  EXPECT_EQ(pub.at("format"), "imucal-signing-public-key/1");
  EXPECT_FALSE(pub.contains("secret_key")) << pub.dump();

  const KeyPair read = read_key_file(path);
  EXPECT_EQ(read.public_key, lab.public_key);
  EXPECT_EQ(read.secret_key, lab.secret_key);
  EXPECT_EQ(read_public_key(path + ".pub"), lab.public_key);
  EXPECT_EQ(read_public_key(path), lab.public_key);
  // A key read back signs documents its public key verifies.
  EXPECT_TRUE(verify_document(sign_document(certificate(), kCertificate, read), read_public_key(path + ".pub"))
                  .verified());
}

TEST(SigningKeyFile, WriteRefusesToOverwriteNamingTheFile) {
  const fs::path d = fresh_dir("signing-overwrite");
  const std::string path = (d / "lab.key").string();
  const KeyPair first = generate_key_pair();
  write_key_file(path, first);
  try {
    write_key_file(path, generate_key_pair());
    ADD_FAILURE() << "a key file was overwritten";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(path + " already exists"), std::string::npos) << e.what();
  }
  EXPECT_EQ(read_key_file(path).public_key, first.public_key);
  // Only the .pub left over from an earlier key: refused too, and no key file is left without it.
  const std::string second = (d / "second.key").string();
  std::ofstream(second + ".pub") << "{}";
  try {
    write_key_file(second, generate_key_pair());
    ADD_FAILURE() << "a public key file was overwritten";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find(second + ".pub already exists"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(second));
}

TEST(SigningKeyFile, AKeyFileOthersMayReadIsRefusedNamingChmod) {
  const fs::path d = fresh_dir("signing-mode");
  const std::string path = (d / "lab.key").string();
  write_key_file(path, generate_key_pair());
  for (const fs::perms perms : {fs::perms(0640), fs::perms(0604), fs::perms(0620)}) {
    fs::permissions(path, perms);
    try {
      read_key_file(path);
      ADD_FAILURE() << "a key file of mode " << std::oct << static_cast<unsigned>(perms) << " was read";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("chmod 600 " + path), std::string::npos) << e.what();
    }
  }
  fs::permissions(path, fs::perms(0600));
  EXPECT_NO_THROW(read_key_file(path));
}

TEST(SigningKeyFile, AMalformedKeyFileIsRefusedNamingTheKey) {
  const fs::path d = fresh_dir("signing-malformed");
  const std::string good_path = (d / "good.key").string();
  const KeyPair lab = generate_key_pair();
  write_key_file(good_path, lab);
  const json good = json::parse(std::ifstream(good_path));
  json other_secret = good;
  other_secret["secret_key"] = json::parse(std::ifstream(good_path))["secret_key"];
  {
    const std::string other_path = (d / "other.key").string();
    write_key_file(other_path, generate_key_pair());
    other_secret["secret_key"] = json::parse(std::ifstream(other_path))["secret_key"];
  }
  json no_secret = good;
  no_secret.erase("secret_key");
  json short_public = good;
  short_public["public_key"] = "AAAA";
  json wrong_fingerprint = good;
  wrong_fingerprint["fingerprint"] = fingerprint(generate_key_pair().public_key);
  json numeric_created = good;
  numeric_created["created"] = 2026;
  json unknown = good;
  unknown["passphrase"] = "x";
  json wrong_format = good;
  wrong_format["format"] = "imucal-signing-public-key/1";
  int n = 0;
  for (const auto& [document, words] :
       std::vector<std::pair<json, std::string>>{{no_secret, "'secret_key' is missing"},
                                                 {other_secret, "'secret_key' does not belong to 'public_key'"},
                                                 {short_public, "'public_key' is not the base64"},
                                                 {wrong_fingerprint, "'fingerprint'"},
                                                 {numeric_created, "'created' must be a string"},
                                                 {unknown, "unknown key 'passphrase'"},
                                                 {wrong_format, "'format' is 'imucal-signing-public-key/1'"}}) {
    const std::string path = (d / ("bad-" + std::to_string(n++) + ".key")).string();
    std::ofstream(path) << document.dump(2);
    fs::permissions(path, fs::perms(0600));
    try {
      read_key_file(path);
      ADD_FAILURE() << "read: " << document.dump();
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(path + ": "), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  }
  const std::string not_json = (d / "not-json.key").string();
  std::ofstream(not_json) << "secret";
  fs::permissions(not_json, fs::perms(0600));
  EXPECT_THROW(read_key_file(not_json), std::runtime_error);
  EXPECT_THROW(read_public_key((d / "missing.pub").string()), std::runtime_error);
}

// The bytes signed are recomputed by the verifier from the parsed file: they must come out the
// same after a write and a read, whatever the content holds.
TEST(SigningCanonicalJson, StableThroughParseAndDump) {
  const json content = json::parse(R"({
    "z": 1, "a": {"y": [1.5, 0.1, 1e-300, 6.02214076e23, -0.0, 2.0, 123456789012345678, -7],
                  "b": {"deep": {"deeper": [{"k": true}, null, "x"]}}},
    "unicode": "Zoë Müller, 温度 25 °C, \u00b1 0.5 \ud83d\ude80, tab\there \"quoted\" back\\slash",
    "M": "capital keys sort before lower case", "": "empty key"})");
  const std::string canonical = canonical_json(content);
  EXPECT_EQ(canonical, content.dump());
  EXPECT_EQ(canonical.find('\n'), std::string::npos);
  EXPECT_EQ(canonical.find(": "), std::string::npos);
  EXPECT_EQ(canonical.rfind(R"({"":"empty key","M":)", 0), 0u) << canonical;
  // Through the text a file holds, pretty-printed or not, several times over.
  json again = content;
  for (int round = 0; round < 3; ++round) {
    again = json::parse(again.dump(round));
    EXPECT_EQ(canonical_json(again), canonical) << "round " << round;
  }
  // Doubles come back bit for bit, so their text does too.
  EXPECT_EQ(again["a"]["y"][1].get<double>(), 0.1);
  EXPECT_EQ(again["a"]["y"][2].get<double>(), 1e-300);
  EXPECT_EQ(canonical_json(json::parse("0.30000000000000004")), "0.30000000000000004");
  EXPECT_EQ(canonical_json(json::parse("2.0")), "2.0");
  // The UTF-8 is written as it is, not escaped: the signed bytes are those of the text a person reads.
  EXPECT_NE(canonical.find("Zoë Müller, 温度 25 °C"), std::string::npos) << canonical;
  // The key order of the text signed is not that of the text read.
  EXPECT_EQ(canonical_json(json::parse(R"({"b": {"d": 1, "c": 2}, "a": 0})")),
            canonical_json(json::parse(R"({"a":0,"b":{"c":2,"d":1}})")));
}
