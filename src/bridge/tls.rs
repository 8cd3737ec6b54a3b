//! Modbus/TCP Security (the Modbus Organization's "MODBUS/TCP Security" protocol
//! specification): Modbus TCP inside TLS 1.2 or later with mutual authentication — the client
//! must present a certificate signed by `--client-ca` (and not revoked by `--crl`), or the
//! handshake fails — and authorisation by the role the client's certificate carries in the
//! role extension (OID 1.3.6.1.4.1.50316.802.1, a UTF8String), mapped to rules by `--role`.
//! A client whose certificate has no role, or a role no rule names, is answered exception 01
//! (Illegal Function) for every request, as the specification says for unauthorised requests;
//! each refusal is counted. Certificates, key, CA and CRL are read again on SIGHUP.

use std::sync::{Arc, RwLock};

use anyhow::Context as _;
use clap::Args;
use tokio_rustls::TlsAcceptor;
use tokio_rustls::rustls;
use tokio_rustls::rustls::pki_types::pem::PemObject as _;
use tokio_rustls::rustls::pki_types::{CertificateDer, CertificateRevocationListDer, PrivateKeyDer};

/// The role extension's OID (MODBUS/TCP Security, "Role-Based Client Authorization").
pub const ROLE_OID: &str = "1.3.6.1.4.1.50316.802.1";

/// `--listen-tls` and its certificates and roles.
#[derive(Debug, Clone, Args, Default)]
pub struct TlsArgs {
    /// Serve Modbus/TCP Security (TLS, client certificates required) here, e.g. 0.0.0.0:802;
    /// alongside the plain listeners, under the same allow-lists.
    #[arg(long, value_name = "ADDR:PORT", requires_all = ["cert", "key", "client_ca"])]
    pub listen_tls: Option<String>,
    /// The bridge's certificate chain (PEM).
    #[arg(long, value_name = "FILE")]
    pub cert: Option<std::path::PathBuf>,
    /// The bridge's private key (PEM).
    #[arg(long, value_name = "FILE")]
    pub key: Option<std::path::PathBuf>,
    /// The CA(s) that sign client certificates (PEM); others fail the handshake.
    #[arg(long, value_name = "FILE")]
    pub client_ca: Option<std::path::PathBuf>,
    /// Certificate revocation lists (PEM) for client certificates.
    #[arg(long, value_name = "FILE")]
    pub crl: Vec<std::path::PathBuf>,
    /// What a role may do (repeatable, once per role): `NAME=RULES`, RULES `;`-separated from
    /// `functions:3,4,6` (only these codes), `units:1-10,17` (only these serial addresses, as the
    /// request reaches the line after --map-unit), `read-only` (only what cannot change a
    /// device), `all` (everything, said on purpose). `--role viewer=read-only --role
    /// operator=units:1-20`. A role no rule names may do nothing; a role without rules is refused.
    #[arg(long, value_name = "NAME=RULES")]
    pub role: Vec<String>,
    /// Only these client addresses may connect to the TLS listener (repeatable; default: the
    /// plain listeners' --allow-ip).
    #[arg(long, value_name = "NET", value_parser = crate::cli::numbers::ip_net)]
    pub tls_allow_ip: Vec<mbtap_gateway::admit::IpNet>,
}

/// What one role may do: the gateway core's rules (`mbtap_gateway::admit::RoleRules`).
pub type Policy = mbtap_gateway::admit::RoleRules;

/// Roles by name.
pub use mbtap_gateway::admit::Roles;

/// `--role NAME=RULES` values.
///
/// # Errors
/// Which value is wrong and why.
pub fn parse_roles(values: &[String]) -> anyhow::Result<Roles> {
    Ok(mbtap_gateway::admit::parse_roles(values)?)
}

/// The role a client certificate carries, if any.
#[must_use]
pub fn role_of(cert: &[u8]) -> Option<String> {
    let (_, cert) = x509_parser::parse_x509_certificate(cert).ok()?;
    let ext = cert.extensions().iter().find(|e| e.oid.to_id_string() == ROLE_OID)?;
    // A DER UTF8String (tag 0x0C): short or long form length.
    let v = ext.value;
    let (&tag, rest) = v.split_first()?;
    if tag != 0x0C {
        return None;
    }
    let (&len, rest) = rest.split_first()?;
    let (len, rest) = if len < 0x80 {
        (usize::from(len), rest)
    } else {
        let n = usize::from(len & 0x7F);
        let (bytes, rest) = (rest.get(..n)?, rest.get(n..)?);
        (bytes.iter().fold(0usize, |a, &b| a.saturating_mul(256).saturating_add(usize::from(b))), rest)
    };
    String::from_utf8(rest.get(..len)?.to_vec()).ok()
}

fn read(path: &std::path::Path, what: &str) -> anyhow::Result<Vec<u8>> {
    std::fs::read(path).with_context(|| format!("{what} {}: cannot read it", path.display()))
}

/// The acceptor the files make.
///
/// # Errors
/// A file cannot be read or holds no usable certificate or key.
pub fn acceptor(args: &TlsArgs) -> anyhow::Result<TlsAcceptor> {
    let (Some(cert), Some(key), Some(ca)) = (&args.cert, &args.key, &args.client_ca) else {
        anyhow::bail!("--listen-tls needs --cert, --key and --client-ca");
    };
    let chain = CertificateDer::pem_slice_iter(&read(cert, "--cert")?)
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| anyhow::anyhow!("--cert {}: {e:?}", cert.display()))?;
    anyhow::ensure!(!chain.is_empty(), "--cert {}: no certificate in it", cert.display());
    let key = PrivateKeyDer::from_pem_slice(&read(key, "--key")?)
        .map_err(|e| anyhow::anyhow!("--key {}: no private key in it ({e:?})", key.display()))?;
    let mut roots = rustls::RootCertStore::empty();
    for c in CertificateDer::pem_slice_iter(&read(ca, "--client-ca")?) {
        let c = c.map_err(|e| anyhow::anyhow!("--client-ca {}: {e:?}", ca.display()))?;
        roots.add(c).with_context(|| format!("--client-ca {}", ca.display()))?;
    }
    anyhow::ensure!(!roots.is_empty(), "--client-ca {}: no certificate in it", ca.display());
    let mut crls = Vec::new();
    for path in &args.crl {
        for c in CertificateRevocationListDer::pem_slice_iter(&read(path, "--crl")?) {
            crls.push(c.map_err(|e| anyhow::anyhow!("--crl {}: {e:?}", path.display()))?);
        }
    }
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let verifier = rustls::server::WebPkiClientVerifier::builder_with_provider(Arc::new(roots), Arc::clone(&provider))
        .with_crls(crls)
        .build()
        .context("--client-ca: building the client verifier")?;
    // TLS 1.2 and 1.3 only (MODBUS/TCP Security requires TLS 1.2 at least).
    let config = rustls::ServerConfig::builder_with_provider(provider)
        .with_protocol_versions(&[&rustls::version::TLS13, &rustls::version::TLS12])
        .context("TLS versions")?
        .with_client_cert_verifier(verifier)
        .with_single_cert(chain, key)
        .with_context(|| format!("--cert {} with --key", cert.display()))?;
    Ok(TlsAcceptor::from(Arc::new(config)))
}

/// Certificates the CRLs revoke: (issuer name DER, serial number bytes).
pub type Revoked = std::collections::BTreeSet<(Vec<u8>, Vec<u8>)>;

/// What the `--crl` files revoke, read with x509-parser (rustls checks them at the handshake;
/// this set re-checks the sessions already open when the files are reloaded).
///
/// # Errors
/// A file that cannot be read or holds a list that does not parse.
pub fn revoked(args: &TlsArgs) -> anyhow::Result<Revoked> {
    let mut out = Revoked::new();
    for path in &args.crl {
        for der in CertificateRevocationListDer::pem_slice_iter(&read(path, "--crl")?) {
            let der = der.map_err(|e| anyhow::anyhow!("--crl {}: {e:?}", path.display()))?;
            let (_, crl) = x509_parser::parse_x509_crl(der.as_ref())
                .map_err(|e| anyhow::anyhow!("--crl {}: {e}", path.display()))?;
            let issuer = crl.issuer().as_raw().to_vec();
            for r in crl.iter_revoked_certificates() {
                out.insert((issuer.clone(), r.raw_serial().to_vec()));
            }
        }
    }
    Ok(out)
}

/// The (issuer, serial) a client certificate is known by in a CRL.
#[must_use]
pub fn identity(cert: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let (_, cert) = x509_parser::parse_x509_certificate(cert).ok()?;
    Some((cert.issuer().as_raw().to_vec(), cert.raw_serial().to_vec()))
}

/// The listener's TLS state: the acceptor (replaced on SIGHUP), the roles, and what the CRLs
/// revoke now (open sessions watch it: a client revoked by a reloaded CRL is disconnected).
#[derive(Clone)]
pub struct Tls {
    pub acceptor: Arc<RwLock<TlsAcceptor>>,
    pub roles: Arc<Roles>,
    pub revoked: Arc<tokio::sync::watch::Sender<Arc<Revoked>>>,
}

impl std::fmt::Debug for Tls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Tls").field("roles", &self.roles).finish_non_exhaustive()
    }
}

impl Tls {
    /// Loads the files; a task reloads them on SIGHUP (keeping the old ones when the new ones
    /// do not load, and saying so).
    ///
    /// # Errors
    /// As [`acceptor`].
    pub fn start(args: &TlsArgs, roles: Arc<Roles>) -> anyhow::Result<Self> {
        let tls = Self {
            acceptor: Arc::new(RwLock::new(acceptor(args)?)),
            roles,
            revoked: Arc::new(tokio::sync::watch::channel(Arc::new(revoked(args)?)).0),
        };
        let (slot, list, args) = (Arc::clone(&tls.acceptor), Arc::clone(&tls.revoked), args.clone());
        tokio::spawn(async move {
            let Ok(mut hup) = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::hangup()) else { return };
            while hup.recv().await.is_some() {
                match acceptor(&args).and_then(|a| Ok((a, revoked(&args)?))) {
                    Ok((a, r)) => {
                        if let Ok(mut s) = slot.write() {
                            *s = a;
                        }
                        // Sessions already open re-check their certificate against it.
                        list.send_replace(Arc::new(r));
                        eprintln!("mbtap: SIGHUP: certificates, key, CA and CRLs reloaded");
                    }
                    Err(e) => eprintln!("mbtap: SIGHUP: keeping the previous certificates: {e:#}"),
                }
            }
        });
        Ok(tls)
    }

    /// Completes when the certificate `cert` is revoked by the CRLs in force (now or after a
    /// reload); never for a certificate that cannot be read (the handshake accepted it).
    pub async fn revocation(&self, cert: &[u8]) {
        let Some(id) = identity(cert) else { return std::future::pending().await };
        let mut rx = self.revoked.subscribe();
        loop {
            if rx.borrow_and_update().contains(&id) {
                return;
            }
            if rx.changed().await.is_err() {
                return std::future::pending().await;
            }
        }
    }

    /// The acceptor now in force.
    #[must_use]
    pub fn current(&self) -> Option<TlsAcceptor> {
        self.acceptor.read().ok().map(|a| a.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_parse_and_decide() {
        let r = parse_roles(&["viewer=read-only".into(), "op=functions:3,6;units:1-2".into()]).unwrap();
        let viewer = &r["viewer"];
        assert!(viewer.allows(9, &[0x03, 0, 0, 0, 1]));
        assert!(!viewer.allows(9, &[0x06, 0, 0, 0, 1]));
        let op = &r["op"];
        assert!(op.allows(2, &[0x06, 0, 0, 0, 1]));
        assert!(!op.allows(3, &[0x06, 0, 0, 0, 1]), "unit 3 is not the role's");
        assert!(!op.allows(1, &[0x10, 0, 0, 0, 1, 2, 0, 0]), "function 16 is not the role's");
        assert!(parse_roles(&["x=everything".into()]).is_err());
        assert!(parse_roles(&["x".into()]).is_err());
        assert!(parse_roles(&["admin=all".into()]).unwrap()["admin"].allows(1, &[0x06, 0, 0, 0, 1]));
    }

    /// `--role admin=` (a role that would let a client do everything) is refused, and so is a
    /// second `--role admin=…` (never silently replacing the first).
    #[test]
    fn an_empty_or_repeated_role_is_refused() {
        for empty in ["admin=", "admin= ; ;", "=read-only"] {
            let e = parse_roles(&[empty.into()]).unwrap_err().to_string();
            assert!(e.contains("no rules") || e.contains("no name"), "{empty}: {e}");
        }
        let e = parse_roles(&["admin=read-only".into(), "admin=all".into()]).unwrap_err().to_string();
        assert!(e.contains("twice"), "{e}");
    }
}
