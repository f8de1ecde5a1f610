"""A site's identity: its keys, and the Zenoh TLS and access control they make.

``optrack site init`` (:func:`init_site`) makes a folder holding a site
certificate authority (``ca.pem``, and ``ca-key.pem`` that only adds
identities later) and one certificate and private key per node or operator
station (``<name>.pem``, ``<name>-key.pem``). The certificate's common name is
the name, its organisational unit the role (:data:`ROLES`). The operator
copies the folder to each computer of the site and names it in ``bus.keys``.

Every Zenoh link of the site then uses mutual TLS with those keys (Zenoh's
``transport/link/tls``): a process whose certificate does not come from the
site's authority cannot connect at all. Zenoh's ``access_control``, made from
the folder's ``identities.json`` (the common names and roles of the
certificates the authority signed; :func:`access_control`), limits what each
common name may send: a detector node puts its own sensor's detections,
previews, views and status; the tracker its tracks, status and the clock and
calibration answers; only operator stations and the launcher (which acts for
the operator) put parameters and calibrations and send commands.

A ``local`` site (one computer) uses the same mechanism with keys made once,
on first start, in the user's data folder (:func:`local_keys`; folder 0700,
private keys 0600): other users of the computer cannot join it.
"""

from __future__ import annotations

import datetime
import json
import os
import shutil
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from optrack.errors import UserError
from optrack.net.keys import NAME, ROOT, check_name

__all__ = [
    "CA_FILE",
    "CA_KEY_FILE",
    "LOCAL_IDENTITY",
    "ROLES",
    "KeysError",
    "SiteIdentities",
    "access_control",
    "init_site",
    "local_keys",
    "role_of_node",
    "tls_settings",
    "verified_roles",
]

CA_FILE = "ca.pem"
CA_KEY_FILE = "ca-key.pem"
IDENTITIES_FILE = "identities.json"  # common name -> role, for the access control
LOCAL_IDENTITY = "local"  # the one identity of a local site's processes (one user)
#: What each role is: ``station`` (an operator station), ``launcher`` (``optrack run``,
#: acting for the operator), ``tracker``, ``detector``, ``skeleton``, ``outputs``.
ROLES = ("station", "launcher", "tracker", "detector", "skeleton", "outputs")
#: The roles that may put parameters and calibrations and send commands.
OPERATOR_ROLES = ("station", "launcher")
#: The node names whose role is not ``detector`` (a detector node is named by its sensor).
NODE_ROLES = {
    "tracker": "tracker",
    "skeleton": "skeleton",
    "outputs": "outputs",
    "site": "launcher",
}
VALID_DAYS = 3650


class KeysError(UserError):
    """Site keys that are missing, unreadable or not of one authority."""


def role_of_node(name: str) -> str:
    """The role of a node by its name (a detector node bears its sensor's name)."""
    return NODE_ROLES.get(name, "detector")


# ----------------------------------------------------------------- making keys


def _write_private(path: Path, data: bytes) -> None:
    """Write ``data`` readable by this user only (0600), atomically."""
    fd, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        os.fchmod(fd, 0o600)
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.replace(temp, path)
    except BaseException:
        Path(temp).unlink(missing_ok=True)
        raise


def _new_key() -> Any:
    from cryptography.hazmat.primitives.asymmetric import ec

    return ec.generate_private_key(ec.SECP256R1())


def _pem_key(key: Any) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return key.private_bytes(
        serialization.Encoding.PEM,
        serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    )


def _pem_cert(cert: Any) -> bytes:
    from cryptography.hazmat.primitives import serialization

    return cert.public_bytes(serialization.Encoding.PEM)


def _subject(common_name: str, role: str, site: str) -> Any:
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    return x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, f"optrack site {site}"),
            x509.NameAttribute(NameOID.ORGANIZATIONAL_UNIT_NAME, role),
            x509.NameAttribute(NameOID.COMMON_NAME, common_name),
        ]
    )


def _make_ca(folder: Path, site: str) -> tuple[Any, Any]:
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    key = _new_key()
    name = _subject(f"{site} authority", "authority", site)
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(name)
        .issuer_name(name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                key_cert_sign=True,
                crl_sign=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), False)
        .sign(key, hashes.SHA256())
    )
    _write_private(folder / CA_KEY_FILE, _pem_key(key))
    (folder / CA_FILE).write_bytes(_pem_cert(cert))
    return cert, key


def _issue(folder: Path, ca: tuple[Any, Any], name: str, role: str) -> None:
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID

    ca_cert, ca_key = ca
    key = _new_key()
    now = datetime.datetime.now(datetime.UTC)
    site = ca_cert.subject.get_attributes_for_oid(x509.NameOID.ORGANIZATION_NAME)[0].value
    cert = (
        x509.CertificateBuilder()
        .subject_name(_subject(name, role, str(site).removeprefix("optrack site ")))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(minutes=5))
        .not_valid_after(now + datetime.timedelta(days=VALID_DAYS))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .add_extension(
            x509.SubjectAlternativeName(
                [
                    x509.DNSName(name.replace("_", "-").lower()),
                    x509.DNSName("localhost"),
                    x509.IPAddress(ipaddress.ip_address("127.0.0.1")),
                ]
            ),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )
    _write_private(folder / f"{name}-key.pem", _pem_key(key))
    (folder / f"{name}.pem").write_bytes(_pem_cert(cert))


def _load_ca(folder: Path) -> tuple[Any, Any]:
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    key_path = folder / CA_KEY_FILE
    if not key_path.is_file():
        raise KeysError(
            f"{folder} holds the site's certificate but not its authority's key ({CA_KEY_FILE}); "
            "add identities on the computer that ran 'optrack site init' first."
        )
    cert = x509.load_pem_x509_certificate((folder / CA_FILE).read_bytes())
    key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    return cert, key


def init_site(
    folder: str | Path,
    nodes: Iterable[str] = (),
    stations: Iterable[str] = (),
    *,
    site: str = "site",
) -> list[str]:
    """Make (or add to) a site's keys in ``folder``: the authority when there is none yet,
    then one identity per node (its role by :func:`role_of_node`) and per operator station
    not there yet. Returns the names of the identities made now."""
    folder = Path(folder).expanduser()
    wanted: dict[str, str] = {}
    for name in nodes:
        wanted[check_name("node", name)] = role_of_node(name)
    for name in stations:
        if check_name("station", name) in wanted:
            raise KeysError(f"'{name}' is named both as a node and as a station; pick one.")
        wanted[name] = "station"
    for name in wanted:
        if name in (CA_FILE[:-4], CA_KEY_FILE[:-4]) or name.endswith("-key"):
            raise KeysError(f"'{name}' cannot name an identity (its files would clash); rename it.")
    folder.mkdir(parents=True, exist_ok=True)
    os.chmod(folder, 0o700)
    ca = _load_ca(folder) if (folder / CA_FILE).is_file() else _make_ca(folder, site)
    made = []
    for name, role in wanted.items():
        if not (folder / f"{name}.pem").is_file():
            _issue(folder, ca, name, role)
            made.append(name)
    roles = json.dumps(verified_roles(folder), indent=1, sort_keys=True) + "\n"
    (folder / IDENTITIES_FILE).write_text(roles, encoding="utf-8")
    return made


def _read_roles(folder: Path) -> dict[str, str]:
    path = folder / IDENTITIES_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        raise KeysError(
            f"{path} is missing or unreadable; copy the site's whole folder again (or run "
            f"'optrack site init --out {folder}' where its authority's key is)."
        ) from None
    if not isinstance(data, dict):
        raise KeysError(f"{path} is not a list of identities; copy the site's folder again.")
    return {
        str(name): str(role)
        for name, role in data.items()
        if role in ROLES and isinstance(name, str) and NAME.match(name)
    }


def verified_roles(folder: str | Path) -> dict[str, str]:
    """Each certificate in ``folder`` that the site's authority signed, by common name,
    with its role (the certificate's organisational unit); others are left out."""
    from cryptography import x509
    from cryptography.x509.oid import NameOID

    folder = Path(folder).expanduser()
    try:
        ca_cert = x509.load_pem_x509_certificate((folder / CA_FILE).read_bytes())
    except (OSError, ValueError):
        raise KeysError(f"{folder / CA_FILE} is not a readable PEM certificate.") from None
    roles: dict[str, str] = {}
    for path in sorted(folder.glob("*.pem")):
        if path.name == CA_FILE or path.name.endswith("-key.pem"):
            continue
        try:
            cert = x509.load_pem_x509_certificate(path.read_bytes())
            cert.verify_directly_issued_by(ca_cert)
        except Exception:  # unreadable or not signed by the site: left out, never trusted
            continue
        name = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value
        units = cert.subject.get_attributes_for_oid(NameOID.ORGANIZATIONAL_UNIT_NAME)
        role = str(units[0].value) if units else ""
        if name == path.stem and role in ROLES:
            roles[str(name)] = role
    return roles


def local_keys(base: str | Path | None = None) -> Path:
    """This user's keys for ``local`` sites, made on first use and kept (the user's data
    folder, ``$XDG_DATA_HOME/optrack/keys/local``, 0700): one authority and the one
    identity every process of the user's local sites presents."""
    if base is None:
        data = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
        base = Path(data) / "optrack" / "keys"
    folder = Path(base) / LOCAL_IDENTITY
    if (folder / IDENTITIES_FILE).is_file():
        return folder
    Path(base).mkdir(parents=True, exist_ok=True)
    temp = Path(tempfile.mkdtemp(dir=base, prefix=".local-"))
    try:
        init_site(temp, stations=[LOCAL_IDENTITY], site=LOCAL_IDENTITY)
        (temp / CA_KEY_FILE).unlink()  # nothing is ever added: the authority's key goes
        try:
            os.rename(temp, folder)
        except OSError:  # another process made them meanwhile: use those
            if not (folder / IDENTITIES_FILE).is_file():  # a partial folder: made anew
                shutil.rmtree(folder)
                os.rename(temp, folder)
    finally:
        if temp.exists():
            for path in temp.iterdir():
                path.unlink()
            temp.rmdir()
    return folder


# ------------------------------------------------------------- reading keys


class SiteIdentities:
    """The identities of a keys folder (its ``identities.json``, written by
    :func:`init_site`): common name -> role. Read without parsing a certificate (a node
    starts fast); Zenoh checks each certificate against the authority when a link opens,
    and :func:`verified_roles` checks them all."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).expanduser()
        self.ca = self.folder / CA_FILE
        if not self.ca.is_file():
            raise KeysError(
                f"bus.keys {self.folder} holds no site keys ({CA_FILE} is missing); make them "
                "with 'optrack site init --out FOLDER' and copy the folder to this computer."
            )
        self.roles = _read_roles(self.folder)

    def require(self, name: str) -> str:
        """``name`` when the folder holds its certificate and private key."""
        if name not in self.roles or not (self.folder / f"{name}-key.pem").is_file():
            known = ", ".join(sorted(self.roles)) or "none"
            raise KeysError(
                f"the site keys in {self.folder} hold no identity '{name}' (they hold: {known}); "
                f"set bus.identity to one of them or add it with 'optrack site init --out "
                f"{self.folder} --nodes {name}' (or --stations {name})."
            )
        return name


def tls_settings(identities: SiteIdentities, name: str) -> dict[str, Any]:
    """Zenoh's ``transport/link/tls`` for identity ``name``: mutual TLS, the site's
    authority as the only root. Host names are not checked (computers on DHCP): the
    authority and the common name say who is who."""
    identities.require(name)
    cert = str(identities.folder / f"{name}.pem")
    key = str(identities.folder / f"{name}-key.pem")
    return {
        "root_ca_certificate": str(identities.ca),
        "enable_mtls": True,
        "verify_name_on_connect": False,
        "listen_certificate": cert,
        "listen_private_key": key,
        "connect_certificate": cert,
        "connect_private_key": key,
    }


def _own_keys(role: str, name: str) -> tuple[list[str], list[str]]:
    """The keys (under ``optrack/*/``) a non-operator identity may put, and those it may
    answer queries on."""
    put = [f"status/{name}"]
    answer = [f"command/{name}"]
    if role == "detector":
        put += [f"{kind}/{name}" for kind in ("detections", "preview", "board_views")]
        put.append(f"person_clouds/{name}")
    elif role == "tracker":
        put.append("tracks")
        answer += ["clock", "calibration"]
    elif role == "skeleton":
        put.append("skeletons")
    return put, answer


def _common_rules() -> list[dict[str, Any]]:
    """The rules every identity of the site shares, and the operators' one."""
    every = f"{ROOT}/**"
    return [
        {
            "id": "receive",
            "messages": ["put", "delete", "query", "reply", "declare_subscriber"]
            + ["declare_queryable", "liveliness_token", "declare_liveliness_subscriber"]
            + ["liveliness_query"],
            "flows": ["egress"],
            "permission": "allow",
            "key_exprs": [every],
        },
        {
            "id": "listen",
            "messages": ["declare_subscriber", "declare_liveliness_subscriber"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": [every],
        },
        {
            "id": "ask",
            "messages": ["query"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": [f"{ROOT}/*/clock", f"{ROOT}/*/calibration"],
        },
        {
            "id": "operate",
            "messages": ["put", "delete", "query", "reply", "declare_queryable"],
            "flows": ["ingress"],
            "permission": "allow",
            "key_exprs": [every],
        },
    ]


def access_control(identities: SiteIdentities) -> dict[str, Any]:
    """Zenoh's ``access_control`` for the site: deny by default; everyone of the site may
    subscribe, receive anything and ask for the clock and the calibration; an operator
    (station, launcher) may do anything on the site's keys; any other identity puts and
    answers only on its own keys."""
    everyone = [{"id": f"id-{name}", "cert_common_names": [name]} for name in identities.roles]
    rules = _common_rules()
    policies: list[dict[str, Any]] = [
        {
            "id": "everyone",
            "rules": ["receive", "listen", "ask"],
            "subjects": [s["id"] for s in everyone],
        }
    ]
    operators = [f"id-{n}" for n, role in identities.roles.items() if role in OPERATOR_ROLES]
    if operators:
        policies.append({"id": "operators", "rules": ["operate"], "subjects": operators})
    for name, role in identities.roles.items():
        if role in OPERATOR_ROLES:
            continue
        put, answer = _own_keys(role, name)
        rules.append(
            {
                "id": f"put-{name}",
                "messages": ["put"],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": [f"{ROOT}/*/{key}" for key in put],
            }
        )
        rules.append(
            {
                "id": f"answer-{name}",
                "messages": ["declare_queryable", "reply"],
                "flows": ["ingress"],
                "permission": "allow",
                "key_exprs": [f"{ROOT}/*/{key}" for key in answer],
            }
        )
        policies.append(
            {
                "id": f"own-{name}",
                "rules": [f"put-{name}", f"answer-{name}"],
                "subjects": [f"id-{name}"],
            }
        )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": everyone,
        "policies": policies,
    }
