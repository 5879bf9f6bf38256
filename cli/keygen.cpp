// imucal keygen: the lab's Ed25519 signing key (docs/signing.md).
#include "cli/commands.hpp"

#include <cstdio>
#include <filesystem>
#include <string>

#include "signing/signing.hpp"

namespace imucal::cli {

// `imucal keygen --out FILE`: FILE (the secret key, mode 0600) and FILE.pub; never over a key.
int run_keygen(const std::string& out_path) {
  const signing::KeyPair key = signing::generate_key_pair();
  signing::write_key_file(out_path, key);
  // Absolute: the daemon's configuration is read from another working directory.
  const std::string path = std::filesystem::absolute(out_path).lexically_normal().string();
  std::printf("wrote the signing key %s (mode 0600: the lab's secret; keep it on the daemon's machine and in the "
              "lab's backups only)\n",
              path.c_str());
  std::printf("and its public key %s.pub (mode 0644: give it to anyone who verifies the lab's documents)\n",
              path.c_str());
  std::printf("fingerprint: %s\n", signing::fingerprint(key.public_key).c_str());
  std::printf("in imucald's configuration: \"certificates\": {\"signing_key_file\": \"%s\"}\n", path.c_str());
  std::printf("verify a signed document: imucal verify DOCUMENT.json --key %s.pub  (or --fingerprint with the "
              "fingerprint above)\n",
              path.c_str());
  return 0;
}

}  // namespace imucal::cli
