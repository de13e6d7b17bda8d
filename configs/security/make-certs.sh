#!/bin/sh
# Make a throwaway certificate authority and certificates for fusion's TLS and access control.
#
#   configs/security/make-certs.sh OUTDIR [--days N] [--host NAME]... [CLIENT_NAME]...
#
# Writes, in OUTDIR (created if missing; existing files are overwritten):
#   ca.pem, ca-key.pem                    the certificate authority (keep ca-key.pem offline)
#   fusion-service.pem, -key.pem          the service's certificate: common name "fusion-service",
#                                         valid for localhost and 127.0.0.1 plus every --host
#   CLIENT_NAME.pem, CLIENT_NAME-key.pem  one client certificate per name; the common name is
#                                         CLIENT_NAME, the identity zenoh's access control sees
# Keys are EC P-256 (PKCS#8), certificates X.509 v3 signed with SHA-256, valid N days (default 30).
# For production, use your own CA and keep the private keys readable by their owner only.
set -eu

usage() { echo "usage: $0 OUTDIR [--days N] [--host NAME]... [CLIENT_NAME]..." >&2; exit 2; }
[ $# -ge 1 ] || usage
out=$1; shift
days=30
hosts=""
clients=""
while [ $# -gt 0 ]; do
    case $1 in
        --days) [ $# -ge 2 ] || usage; days=$2; shift 2 ;;
        --host) [ $# -ge 2 ] || usage; hosts="$hosts $2"; shift 2 ;;
        -*) usage ;;
        *) clients="$clients $1"; shift ;;
    esac
done
command -v openssl >/dev/null || { echo "$0: openssl not found" >&2; exit 1; }
mkdir -p "$out"
umask 077

key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

# sign NAME EXTENSIONS: a certificate for common name NAME signed by the CA
sign() {
    key "$out/$1-key.pem"
    openssl req -new -key "$out/$1-key.pem" -subj "/CN=$1" -out "$out/$1.csr"
    printf '%s\n' "$2" > "$out/$1.ext"
    openssl x509 -req -in "$out/$1.csr" -CA "$out/ca.pem" -CAkey "$out/ca-key.pem" -CAcreateserial \
        -days "$days" -sha256 -extfile "$out/$1.ext" -out "$out/$1.pem" 2>/dev/null
    rm -f "$out/$1.csr" "$out/$1.ext"
}

key "$out/ca-key.pem"
openssl req -x509 -new -key "$out/ca-key.pem" -subj "/CN=fusion test CA" -days "$days" -sha256 \
    -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
    -out "$out/ca.pem"

san="DNS:localhost,IP:127.0.0.1"
for h in $hosts; do
    case $h in
        *[!0-9.]*) san="$san,DNS:$h" ;;
        *) san="$san,IP:$h" ;;
    esac
done
sign fusion-service "basicConstraints=CA:FALSE
keyUsage=critical,digitalSignature
extendedKeyUsage=serverAuth,clientAuth
subjectAltName=$san"

for c in $clients; do
    case $c in
        *[!A-Za-z0-9_.-]*) echo "$0: client name '$c' must be letters, digits, '_', '-', '.'" >&2; exit 2 ;;
    esac
    sign "$c" "basicConstraints=CA:FALSE
keyUsage=critical,digitalSignature
extendedKeyUsage=clientAuth
subjectAltName=DNS:$c"
done
rm -f "$out/ca.srl"
echo "certificates in $out: ca.pem fusion-service.pem$(for c in $clients; do printf ' %s.pem' "$c"; done)"
