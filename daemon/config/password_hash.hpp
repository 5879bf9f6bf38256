// Password hashes for the browser sign-in (libsodium's crypto_pwhash_str: Argon2id, salted, with
// its cost in the string). The configuration holds only hashes, made by `imucal passwd`; a
// plain-text password there is refused (config.cpp).
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace imucal::daemon {

// The shortest password taken (`imucal passwd`, the lab's accounts).
inline constexpr std::size_t kMinPasswordLength = 8;

// A new hash of `password` ("$argon2id$v=19$m=...,t=...,p=1$salt$hash"). Throws when libsodium
// cannot work (no memory).
std::string hash_password(std::string_view password);

// Whether `password` matches `hash` (constant time in the password; false for a malformed hash).
bool verify_password(const std::string& hash, std::string_view password);

// Whether the text has the form of a hash hash_password makes (checked when the configuration is read).
bool is_password_hash(std::string_view text);

}  // namespace imucal::daemon
