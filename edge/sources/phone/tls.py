"""The phone page's HTTPS certificate: a local certificate authority made once, and a server
certificate it signs for this host's names and addresses (docs/phone.md).

Why a CA and not one self-signed certificate: a phone trusts the CA once (`ca.pem`, served at
/ca.pem); when the host's address changes, only the server certificate is issued again and the
phone keeps trusting it. Browsers need HTTPS for motion sensors and the camera (a secure context).

Files in `tls_dir` (created 0700; keys 0600): `ca.pem`, `ca-key.pem`, `cert.pem`, `key.pem`.
The server certificate is issued again when a name or address is missing from it, when it ends
within RENEW_DAYS, or when it is not signed by the CA in the folder. Validity 397 days: iOS
refuses server certificates valid for more than 825 days, and 397 keeps the way open to the
398-day rule of public CAs.
"""

from __future__ import annotations

import datetime
import ipaddress
import logging
import os
import socket
from pathlib import Path

from cryptography import x509
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from protocol.errors import ConfigError

log = logging.getLogger(__name__)

CA_DAYS = 3650
SERVER_DAYS = 397
RENEW_DAYS = 30
CA_NAME = "reckon phone CA"


def host_names(bind_host: str = "") -> tuple[list[str], list[str]]:
    """(DNS names, IP addresses) a phone may use to reach this host: the hostname, its FQDN,
    localhost, loopback, every address the hostname resolves to, the address of the default
    route's interface (found with a UDP socket that sends nothing) and `bind_host` itself."""
    names = {"localhost", socket.gethostname(), socket.getfqdn()}
    addresses = {"127.0.0.1", "::1"}
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None):
            addresses.add(str(info[4][0]))
    except OSError:
        pass
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("192.0.2.1", 9))  # TEST-NET-1: picks the outgoing interface, no packet sent
            addresses.add(probe.getsockname()[0])
    except OSError:
        pass
    if bind_host:
        try:
            addresses.add(str(ipaddress.ip_address(bind_host)))
        except ValueError:
            names.add(bind_host)
    addresses -= {"0.0.0.0", "::"}
    return sorted(n for n in names if n), sorted(addresses)


def _write_private(path: Path, data: bytes) -> None:
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(descriptor, "wb") as file:
        file.write(data)


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def _now() -> datetime.datetime:
    return datetime.datetime.now(datetime.timezone.utc)


def _load_or_make_ca(folder: Path) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    cert_path, key_path = folder / "ca.pem", folder / "ca-key.pem"
    if cert_path.exists() and key_path.exists():
        try:
            cert = x509.load_pem_x509_certificate(cert_path.read_bytes())
            key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
        except (ValueError, OSError) as error:
            raise ConfigError(f"{folder}: cannot read the phone CA ({error}); move the folder away to make a new "
                              "one (phones then trust the new ca.pem again)") from None
        if not isinstance(key, ec.EllipticCurvePrivateKey):
            raise ConfigError(f"{key_path}: expected an EC private key")
        return cert, key
    key = ec.generate_private_key(ec.SECP256R1())
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, f"{CA_NAME} ({socket.gethostname()})")])
    now = _now()
    cert = (x509.CertificateBuilder().subject_name(name).issuer_name(name).public_key(key.public_key())
            .serial_number(x509.random_serial_number()).not_valid_before(now - datetime.timedelta(days=1))
            .not_valid_after(now + datetime.timedelta(days=CA_DAYS))
            .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
            .add_extension(x509.KeyUsage(digital_signature=True, key_cert_sign=True, crl_sign=True,
                                         content_commitment=False, key_encipherment=False, data_encipherment=False,
                                         key_agreement=False, encipher_only=False, decipher_only=False), critical=True)
            .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
            .sign(key, hashes.SHA256()))
    _write_private(key_path, _key_pem(key))
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    log.warning("made a new phone CA in %s: phones must trust %s once (docs/phone.md)", folder, cert_path)
    return cert, key


def _covers(cert: x509.Certificate, ca: x509.Certificate, names: list[str], addresses: list[str]) -> bool:
    if cert.issuer != ca.subject or cert.not_valid_after_utc - _now() < datetime.timedelta(days=RENEW_DAYS):
        return False
    try:
        cert.verify_directly_issued_by(ca)
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except (ValueError, TypeError, x509.ExtensionNotFound, x509.InvalidSignature):
        return False
    have_names = set(san.get_values_for_type(x509.DNSName))
    have_addresses = {str(a) for a in san.get_values_for_type(x509.IPAddress)}
    return set(names) <= have_names and set(addresses) <= have_addresses


def ensure_certificate(tls_dir: Path | str, bind_host: str = "") -> tuple[Path, Path]:
    """(cert.pem, key.pem) for the HTTPS server in `tls_dir`, made or renewed as needed (see the
    module docstring). ConfigError naming the folder if it cannot be created or read."""
    folder = Path(tls_dir)
    try:
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    except OSError as error:
        raise ConfigError(f"--source phone://...?tls_dir={folder}: cannot create it ({error.strerror})") from None
    ca, ca_key = _load_or_make_ca(folder)
    names, addresses = host_names(bind_host)
    cert_path, key_path = folder / "cert.pem", folder / "key.pem"
    if cert_path.exists() and key_path.exists():
        try:
            if _covers(x509.load_pem_x509_certificate(cert_path.read_bytes()), ca, names, addresses):
                return cert_path, key_path
        except ValueError:
            pass  # unreadable: issue a new one below
    key = ec.generate_private_key(ec.SECP256R1())
    now = _now()
    san = [x509.DNSName(n) for n in names] + [x509.IPAddress(ipaddress.ip_address(a)) for a in addresses]
    cert = (x509.CertificateBuilder()
            .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, socket.gethostname() or "reckon")]))
            .issuer_name(ca.subject).public_key(key.public_key()).serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(days=1)).not_valid_after(now + datetime.timedelta(days=SERVER_DAYS))
            .add_extension(x509.SubjectAlternativeName(san), critical=False)
            .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
            .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
            .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
            .sign(ca_key, hashes.SHA256()))
    _write_private(key_path, _key_pem(key))
    cert_path.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    log.info("issued the phone server certificate %s for %s", cert_path, ", ".join(names + addresses))
    return cert_path, key_path
