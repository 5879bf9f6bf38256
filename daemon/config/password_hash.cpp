#include "daemon/config/password_hash.hpp"

#include <sodium.h>

#include <stdexcept>

namespace imucal::daemon {

namespace {

void init_sodium() {
  // Safe to call from several threads and more than once; < 0 only when no entropy source exists.
  if (sodium_init() < 0) throw std::runtime_error("libsodium cannot start (no random source)");
}

}  // namespace

std::string hash_password(std::string_view password) {
  init_sodium();
  char out[crypto_pwhash_STRBYTES];
  // The interactive limits (64 MiB, a fraction of a second): a sign-in stays quick, a stolen
  // configuration stays expensive to guess from.
  if (crypto_pwhash_str(out, password.data(), password.size(), crypto_pwhash_OPSLIMIT_INTERACTIVE,
                        crypto_pwhash_MEMLIMIT_INTERACTIVE) != 0)
    throw std::runtime_error("cannot hash the password: out of memory");
  return out;
}

bool verify_password(const std::string& hash, std::string_view password) {
  init_sodium();
  if (!is_password_hash(hash)) return false;
  return crypto_pwhash_str_verify(hash.c_str(), password.data(), password.size()) == 0;
}

bool is_password_hash(std::string_view text) {
  return (text.rfind("$argon2id$", 0) == 0 || text.rfind("$argon2i$", 0) == 0) && text.size() < crypto_pwhash_STRBYTES;
}

}  // namespace imucal::daemon
