#!/bin/sh
# The venue's TLS certificates for the Zenoh router, made with openssl.
#
#   make-certs.sh DIR ca                      venue CA: DIR/ca.key, DIR/ca.pem (10 years)
#   make-certs.sh DIR server NAME [SAN...]    router: DIR/NAME.key, DIR/NAME.pem signed by the CA
#                                             SANs: DNS names or IP addresses the clients dial
#                                             (default: NAME); clients check them
#   make-certs.sh DIR client NAME             a client certificate (only for mutual TLS,
#                                             `enable_mtls: true` on the router)
#
# Keys are ECDSA P-256 in PKCS#8 (what rustls, Zenoh's TLS, reads). The CA key signs every other
# certificate: keep it off the hub once the certificates are made. An existing file is never
# overwritten (delete it to make a new one), so re-running is safe.
set -eu

usage() {
    echo "usage: $0 DIR ca | DIR server NAME [SAN...] | DIR client NAME" >&2
    exit 2
}

[ $# -ge 2 ] || usage
dir=$1
kind=$2
shift 2
mkdir -p "$dir"
umask 077  # private keys readable by their owner only

days_ca=3650
days_leaf=825  # the longest validity TLS clients commonly accept for a leaf certificate

new_key() {
    openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null
}

refuse_existing() {
    for file in "$@"; do
        if [ -e "$file" ]; then
            echo "$file exists: not overwritten (delete it to make a new one)" >&2
            exit 1
        fi
    done
}

# Sign DIR/$1.key's request with the CA. $2: extensions (extendedKeyUsage, subjectAltName).
sign() {
    name=$1
    extensions=$2
    [ -e "$dir/ca.key" ] && [ -e "$dir/ca.pem" ] || { echo "no CA in $dir: run '$0 $dir ca' first" >&2; exit 1; }
    new_key "$dir/$name.key"
    printf '%s\n' "basicConstraints=critical,CA:FALSE" "keyUsage=critical,digitalSignature" "$extensions" \
        > "$dir/$name.ext"
    openssl req -new -key "$dir/$name.key" -subj "/CN=$name" -out "$dir/$name.csr"
    openssl x509 -req -in "$dir/$name.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" -CAcreateserial \
        -days "$days_leaf" -sha256 -extfile "$dir/$name.ext" -out "$dir/$name.pem" 2>/dev/null
    rm -f "$dir/$name.csr" "$dir/$name.ext"
    chmod 644 "$dir/$name.pem"
    echo "made $dir/$name.pem and $dir/$name.key"
}

case $kind in
    ca)
        [ $# -eq 0 ] || usage
        refuse_existing "$dir/ca.key" "$dir/ca.pem"
        new_key "$dir/ca.key"
        openssl req -x509 -new -key "$dir/ca.key" -sha256 -days "$days_ca" -subj "/CN=reckon venue CA" \
            -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" \
            -out "$dir/ca.pem"
        chmod 644 "$dir/ca.pem"
        echo "made $dir/ca.pem (give it to every client) and $dir/ca.key (keep it safe, off the hub)"
        ;;
    server)
        [ $# -ge 1 ] || usage
        name=$1
        shift
        [ $# -ge 1 ] || set -- "$name"
        refuse_existing "$dir/$name.key" "$dir/$name.pem"
        sans=""
        for san in "$@"; do
            case $san in
                *:*) entry="IP:$san" ;;  # an IPv6 address
                *[!0-9.]*) entry="DNS:$san" ;;  # anything but digits and dots is a host name
                *) entry="IP:$san" ;;
            esac
            sans="${sans:+$sans,}$entry"
        done
        sign "$name" "$(printf '%s\n%s' "extendedKeyUsage=serverAuth" "subjectAltName=$sans")"
        ;;
    client)
        [ $# -eq 1 ] || usage
        refuse_existing "$dir/$1.key" "$dir/$1.pem"
        sign "$1" "extendedKeyUsage=clientAuth"
        ;;
    *)
        usage
        ;;
esac
