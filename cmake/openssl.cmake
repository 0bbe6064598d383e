find_package(OpenSSL REQUIRED COMPONENTS Crypto)
message(STATUS "OpenSSL ${OPENSSL_VERSION}")
