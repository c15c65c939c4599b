//! Who may subscribe: the group given to the socket file and the optional allow lists of
//! users and groups checked against each peer's credentials (`SO_PEERCRED`), with names
//! resolved to ids once, at start, so that a name that does not exist fails the start instead
//! of locking everyone out later.

use serde::Deserialize;
use tacmesh_publish::AllowedPeers;

/// A user or group in the config: a name (`"robot"`) or a number (`1000`).
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(untagged)]
pub enum Principal {
    Id(u32),
    Name(String),
}

/// Why a user or group named in the config cannot be used.
/// Each message states its cause itself; the cause is a field named `cause`, not `source`, so
/// that a printer of error chains (anyhow's `{:#}`) does not print it a second time.
#[derive(Debug, thiserror::Error)]
pub enum AccessError {
    #[error("config: {key}: there is no {kind} {name:?} on this system")]
    Unknown {
        key: &'static str,
        kind: &'static str,
        name: String,
    },
    #[error("config: {key}: cannot look up the {kind} {name:?}: {cause}")]
    Lookup {
        key: &'static str,
        kind: &'static str,
        name: String,
        cause: nix::Error,
    },
}

/// The group id of `principal` (a name is looked up through NSS, as `getent group` would).
pub fn group_id(principal: &Principal, key: &'static str) -> Result<u32, AccessError> {
    match principal {
        Principal::Id(id) => Ok(*id),
        Principal::Name(name) => nix::unistd::Group::from_name(name)
            .map_err(|cause| AccessError::Lookup {
                key,
                kind: "group",
                name: name.clone(),
                cause,
            })?
            .map(|group| group.gid.as_raw())
            .ok_or_else(|| AccessError::Unknown {
                key,
                kind: "group",
                name: name.clone(),
            }),
    }
}

/// The user id of `principal` (a name is looked up through NSS, as `getent passwd` would).
pub fn user_id(principal: &Principal, key: &'static str) -> Result<u32, AccessError> {
    match principal {
        Principal::Id(id) => Ok(*id),
        Principal::Name(name) => nix::unistd::User::from_name(name)
            .map_err(|cause| AccessError::Lookup {
                key,
                kind: "user",
                name: name.clone(),
                cause,
            })?
            .map(|user| user.uid.as_raw())
            .ok_or_else(|| AccessError::Unknown {
                key,
                kind: "user",
                name: name.clone(),
            }),
    }
}

/// The users listed as members of group `gid` in the group database (`getent group`), whom
/// `SO_PEERCRED` does not show as being in it. A member name that no longer resolves to a user
/// is skipped with a warning: a stale `/etc/group` entry must not stop the daemon.
fn member_uids_of(gid: u32) -> Result<Vec<u32>, AccessError> {
    let lookup = |cause| AccessError::Lookup {
        key: "socket.allow_groups",
        kind: "group",
        name: gid.to_string(),
        cause,
    };
    let Some(group) =
        nix::unistd::Group::from_gid(nix::unistd::Gid::from_raw(gid)).map_err(lookup)?
    else {
        return Ok(Vec::new());
    };
    let mut uids = Vec::with_capacity(group.mem.len());
    for name in &group.mem {
        match nix::unistd::User::from_name(name) {
            Ok(Some(user)) => uids.push(user.uid.as_raw()),
            Ok(None) | Err(_) => tracing::warn!(
                "socket.allow_groups: group {} lists the member {name:?}, who is not a user here; \
                 skipping it",
                group.name
            ),
        }
    }
    Ok(uids)
}

/// The allow lists, resolved; `None` when neither list is given (anyone the socket file's
/// mode lets connect may subscribe). An empty list given on purpose admits nobody by it. An
/// allowed group admits the processes whose primary group it is and the users listed as its
/// members when the daemon starts (a user added later is admitted after a restart).
pub fn allowed_peers(
    users: Option<&[Principal]>,
    groups: Option<&[Principal]>,
) -> Result<Option<AllowedPeers>, AccessError> {
    if users.is_none() && groups.is_none() {
        return Ok(None);
    }
    let uids = users
        .unwrap_or_default()
        .iter()
        .map(|p| user_id(p, "socket.allow_users"))
        .collect::<Result<_, _>>()?;
    let gids: Vec<u32> = groups
        .unwrap_or_default()
        .iter()
        .map(|p| group_id(p, "socket.allow_groups"))
        .collect::<Result<_, _>>()?;
    let mut member_uids = Vec::new();
    for &gid in &gids {
        member_uids.extend(member_uids_of(gid)?);
    }
    member_uids.sort_unstable();
    member_uids.dedup();
    Ok(Some(AllowedPeers {
        uids,
        gids,
        member_uids,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_numbers_resolve() {
        // root is user 0 and group 0 on every Linux system.
        let root = Principal::Name("root".into());
        assert_eq!(user_id(&root, "k").unwrap(), 0);
        assert_eq!(group_id(&root, "k").unwrap(), 0);
        assert_eq!(user_id(&Principal::Id(1234), "k").unwrap(), 1234);
        let peers = allowed_peers(Some(&[root.clone(), Principal::Id(7)]), None)
            .unwrap()
            .unwrap();
        assert_eq!(peers.uids, vec![0, 7]);
        assert!(peers.gids.is_empty());
        assert!(peers.member_uids.is_empty());
        assert_eq!(allowed_peers(None, None).unwrap(), None);
    }

    #[test]
    fn an_unknown_name_is_an_error_naming_it_and_the_key() {
        let ghost = Principal::Name("no-such-tacmesh-user-xyz".into());
        let err = allowed_peers(Some(&[ghost]), None).unwrap_err().to_string();
        assert!(
            err.contains("socket.allow_users") && err.contains("no-such-tacmesh-user-xyz"),
            "{err}"
        );
        let err = group_id(&Principal::Name("no-such-group-xyz".into()), "socket.group")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("socket.group") && err.contains("group"),
            "{err}"
        );
    }

    /// A user added to an allowed group as a supplementary member (`usermod -aG`) is admitted,
    /// although `SO_PEERCRED` reports only the primary group. Checked against this system's
    /// group database: every group that lists members must admit each of them.
    #[test]
    fn supplementary_members_of_an_allowed_group_are_admitted() {
        let Ok(groups) = std::fs::read_to_string("/etc/group") else {
            return;
        };
        for line in groups.lines() {
            let fields: Vec<&str> = line.split(':').collect();
            let [name, _, gid, members] = fields[..] else {
                continue;
            };
            let Ok(gid) = gid.parse::<u32>() else {
                continue;
            };
            let peers = allowed_peers(None, Some(&[Principal::Name(name.into())]))
                .unwrap()
                .unwrap();
            for member in members.split(',').filter(|m| !m.is_empty()) {
                let Ok(Some(user)) = nix::unistd::User::from_name(member) else {
                    continue;
                };
                let uid = user.uid.as_raw();
                // Its primary group is some other group: only the membership admits it.
                let other_gid = gid.wrapping_add(1);
                assert!(
                    tacmesh_publish::AllowedPeers::allows(&peers, uid, other_gid),
                    "{member} (uid {uid}) is a member of {name} but is refused"
                );
            }
        }
    }
}
