#!/bin/bash
# The checks of .ci/systemd-live, run inside its Debian container by tacmesh-live-checks.service
# once systemd has booted. Each check drives the real tacmesh.service with systemctl and judges
# it by what systemd reports (systemctl show: ActiveState, Result, NRestarts, MainPID, ...), by
# the journal and by what subscribers get. One line per check goes to
# /var/lib/tacmesh-live/results:
#   PASS name what was measured
#   FAIL name what went wrong
# written to results.partial as the checks go and renamed to results at the end, so that a run
# cut short leaves no results file (the host then fails). The daemon's journal goes to
# journal.txt beside it. The unit powers the container off when this script ends.
#
# The checks, in order (each starts from the state the one before left):
#   sysusers          the sysusers entry makes user tacmesh, in groups video and dialout
#   ready             `systemctl start` returns (Type=notify: the daemon said READY=1)
#   hardening         the unit's sandbox is really applied to the running daemon
#   default-sensor    the default sensor (the simulated demo scene) works under it
#   subscribe-member  a user whose group is tacmesh gets meshes
#   subscribe-supplementary  so does a user who is only a supplementary member of tacmesh
#   refuse-outsider   a user outside group tacmesh is refused by the socket's permissions
#   refuse-not-allowed root, whom file modes do not stop, is refused by socket.allow_groups
#   journald-restart  `systemctl restart systemd-journald` does not kill or restart the daemon
#   journald-stop     nor does journald stopped for a while, which closes its standard error
#   sigkill-restart   a crash (SIGKILL) is restarted (Restart=on-failure), counted in NRestarts
#   sigterm-stop      `systemctl stop` (SIGTERM) ends with Result=success
#   watchdog          a stalled pipeline (scenes/stall.toml) is killed by the watchdog and
#                     restarted, again and again, counted in NRestarts
set -uo pipefail # not -e: a failed check is written down and the next one runs

out=/var/lib/tacmesh-live
mkdir -p "$out"
partial="$out/results.partial"
: >"$partial"
unit=tacmesh.service
socket=/run/tacmesh/tacmesh.sock
stall_dropin=/run/systemd/system/tacmesh.service.d/stall.conf

# --- helpers -------------------------------------------------------------------------------

# result PASS|FAIL NAME DETAIL...: one line of the results file (and of the console).
result() {
  local verdict=$1 name=$2
  shift 2
  echo "$verdict $name $*" | tee -a "$partial"
}
pass() { result PASS "$@"; }
fail() { result FAIL "$@"; }

# prop NAME: one property of the unit, as `systemctl show` reports it.
prop() { systemctl show -p "$1" --value "$unit"; }

# state: the properties the checks judge by, on one line, for details.
state() {
  echo "ActiveState=$(prop ActiveState) SubState=$(prop SubState) Result=$(prop Result)" \
    "NRestarts=$(prop NRestarts) MainPID=$(prop MainPID)"
}

running() { [ "$(prop ActiveState)" = active ] && [ "$(prop SubState)" = running ]; }

# now: seconds since the epoch, with nanoseconds; since T: seconds from T to now, to 0.1 s.
now() { date +%s.%N; }
since() { awk -v from="$1" -v to="$(now)" 'BEGIN { printf "%.1f", to - from }'; }

# wait_until SECONDS COMMAND...: runs COMMAND every 0.2 s until it succeeds; false after
# SECONDS.
wait_until() {
  local limit=$1
  shift
  local deadline=$((SECONDS + limit))
  until "$@"; do
    [ "$SECONDS" -ge "$deadline" ] && return 1
    sleep 0.2
  done
}

# daemon_log [journalctl options]: the running daemon's own lines (this invocation's output).
daemon_log() {
  journalctl --no-pager -o cat _SYSTEMD_INVOCATION_ID="$(prop InvocationID)" "$@"
}

# subscribe USER COUNT: `tacmesh subscribe` as USER (root: directly) for COUNT updates, at most
# 30 s; sets sub_rc, sub_out (its output, standard error included) and sub_meshes (how many
# updates of objects and planes it printed: `shape …`, `pose …` and `seen …` lines).
subscribe() {
  local user=$1 count=$2
  local command=(timeout 30 tacmesh subscribe --socket "$socket" --count "$count")
  if [ "$user" != root ]; then
    command=(runuser -u "$user" -- "${command[@]}")
  fi
  sub_out="$("${command[@]}" 2>&1)"
  sub_rc=$?
  sub_meshes="$(grep -cE '^(shape|pose|seen) ' <<<"$sub_out")"
}

# first_line TEXT: the first line of TEXT, for details.
first_line() { head -n 1 <<<"$1"; }

echo "tacmesh live checks: $(tacmesh --version 2>&1), $(systemctl --version | head -n 1)"

# --- sysusers: the package's postinst runs `systemd-sysusers tacmesh.conf` ------------------
if systemd-sysusers tacmesh.conf && systemd-sysusers /usr/lib/tacmesh-live/users.conf; then
  groups="$(id -nG tacmesh)"
  if grep -qw video <<<"$groups" && grep -qw dialout <<<"$groups"; then
    pass sysusers "user tacmesh $(id -u tacmesh), groups: $groups;" \
      "test users: $(id tm-member), $(id tm-supplementary), $(id tm-outsider)"
  else
    fail sysusers "user tacmesh is not in video and dialout: $(id tacmesh)"
  fi
else
  fail sysusers "systemd-sysusers failed"
fi

# --- ready: Type=notify, so `systemctl start` returns once the daemon sent READY=1 ----------
started="$(now)"
if timeout 60 systemctl start "$unit"; then
  ready_s="$(since "$started")"
  if running; then
    pass ready "READY=1 after $ready_s s; $(state)"
  else
    fail ready "started, but not running: $(state)"
  fi
else
  fail ready "systemctl start failed after $(since "$started") s: $(state)"
fi

# --- hardening: the sandbox is in force on the running daemon -------------------------------
# Inside a container some settings could be skipped silently; the kernel's view of the process
# says what really holds: no new privileges, a seccomp filter (mode 2), no capabilities, the
# supplementary groups that open the sensors, mount and network namespaces of its own, / read
# only and /home empty in its mount namespace; and systemd logged no warning about the unit (a
# setting it could not apply).
pid="$(prop MainPID)"
if [ "$pid" -gt 0 ] && [ -r "/proc/$pid/status" ]; then
  field() { awk -v key="$1:" '$1 == key { $1 = ""; sub(/^ /, ""); print }' "/proc/$pid/status"; }
  nnp="$(field NoNewPrivs)" seccomp="$(field Seccomp)" capeff="$(field CapEff)"
  capbnd="$(field CapBnd)" gids="$(field Groups)"
  want_gids="$(getent group video | cut -d: -f3) $(getent group dialout | cut -d: -f3)"
  groups_ok=yes
  for gid in $want_gids; do grep -qw "$gid" <<<"$gids" || groups_ok=no; done
  own_ns=yes
  for ns in mnt net ipc uts; do
    [ "$(readlink "/proc/$pid/ns/$ns")" != "$(readlink "/proc/1/ns/$ns")" ] || own_ns="no $ns"
  done
  root_options="$(nsenter --target "$pid" --mount findmnt --noheadings --output OPTIONS /)"
  home="$(nsenter --target "$pid" --mount ls -A /home /root 2>&1 | grep -v -e '^/' -e '^$')"
  manager_warnings="$(journalctl --no-pager -b -o cat -p warning _PID=1 UNIT="$unit")"
  detail="NoNewPrivs=$nnp Seccomp=$seccomp CapEff=$capeff CapBnd=$capbnd Groups=$gids;"
  detail+=" own mnt/net/ipc/uts namespaces: $own_ns; / ${root_options%%,*};"
  detail+=" /home and /root: ${home:-empty}"
  if [ "$nnp" = 1 ] && [ "$seccomp" = 2 ] && [ "$capeff" = 0000000000000000 ] &&
    [ "$capbnd" = 0000000000000000 ] && [ "$groups_ok" = yes ] && [ "$own_ns" = yes ] &&
    [ "${root_options%%,*}" = ro ] && [ -z "$home" ] && [ -z "$manager_warnings" ]; then
    pass hardening "$detail"
  else
    fail hardening "$detail (video, dialout: $want_gids); systemd's warnings:" \
      "$(tr '\n' ';' <<<"$manager_warnings")"
  fi
else
  fail hardening "no running daemon to look at: $(state)"
fi

# --- default-sensor: the config's sensor (the simulated demo scene) works in the sandbox ---
# Its STATUS= line (every 2 s) must show frames, objects and no source errors, and the daemon
# must have logged nothing at warning or above.
status_ok() {
  local status
  status="$(prop StatusText)"
  [[ $status =~ ^([0-9.]+)\ frames/s,\ ([0-9]+)\ objects.*\ ([0-9]+)\ source\ errors$ ]] &&
    [ "${BASH_REMATCH[2]}" -ge 1 ] && [ "${BASH_REMATCH[3]}" = 0 ] &&
    awk -v fps="${BASH_REMATCH[1]}" 'BEGIN { exit !(fps > 0) }'
}
if wait_until 30 status_ok; then
  warnings="$(daemon_log -p warning)"
  if [ -z "$warnings" ]; then
    pass default-sensor "STATUS=\"$(prop StatusText)\"; no warnings in the daemon's log"
  else
    fail default-sensor "the daemon warned: $(tr '\n' ';' <<<"$warnings")"
  fi
else
  fail default-sensor "no frames or objects within 30 s: STATUS=\"$(prop StatusText)\"; $(state);" \
    "log: $(daemon_log -n 5 | tr '\n' ';')"
fi

# --- subscribe-member: a user of group tacmesh gets meshes ----------------------------------
started="$(now)"
subscribe tm-member 5
if [ "$sub_rc" = 0 ] && [ "$sub_meshes" -ge 5 ]; then
  pass subscribe-member "tm-member ($(id -gn tm-member)) got $sub_meshes meshes in" \
    "$(since "$started") s, first: $(grep -m 1 '^shape ' <<<"$sub_out")"
else
  fail subscribe-member "tm-member: exit $sub_rc, $sub_meshes meshes: $(tail -n 2 <<<"$sub_out" | tr '\n' ';')"
fi

# --- subscribe-supplementary: a supplementary member of tacmesh gets meshes too -------------
# SO_PEERCRED reports only the primary group; socket.allow_groups must admit it all the same.
subscribe tm-supplementary 2
if [ "$sub_rc" = 0 ] && [ "$sub_meshes" -ge 2 ]; then
  pass subscribe-supplementary "tm-supplementary ($(id -gn tm-supplementary), also in" \
    "$(id -Gn tm-supplementary | cut -d ' ' -f 2-)) got $sub_meshes meshes"
else
  fail subscribe-supplementary "tm-supplementary ($(id -Gn tm-supplementary)): exit $sub_rc," \
    "$sub_meshes meshes: $(tail -n 2 <<<"$sub_out" | tr '\n' ';')"
fi

# --- refuse-outsider: the socket's directory (0750) and file (0660) keep others out ---------
subscribe tm-outsider 1
if [ "$sub_rc" != 0 ] && [ "$sub_meshes" = 0 ] && grep -q 'Permission denied' <<<"$sub_out"; then
  pass refuse-outsider "tm-outsider ($(id -gn tm-outsider)): exit $sub_rc, 0 meshes:" \
    "$(first_line "$sub_out")"
else
  fail refuse-outsider "tm-outsider: exit $sub_rc, $sub_meshes meshes: $(first_line "$sub_out")"
fi

# --- refuse-not-allowed: the daemon's own check (socket.allow_groups = ["tacmesh"]) --------
# root passes any file mode, so only the daemon's peer-credential check can refuse it: it gets
# a Goodbye saying why instead of the Hello, and the refusal is logged.
subscribe root 1
refusal_logged() { daemon_log | grep -q 'refused a subscriber: uid 0 gid 0'; }
if [ "$sub_rc" != 0 ] && [ "$sub_meshes" = 0 ] && grep -q 'refused this subscriber' <<<"$sub_out" &&
  wait_until 5 refusal_logged; then
  pass refuse-not-allowed "root: exit $sub_rc, 0 meshes: $(first_line "$sub_out"); the daemon:" \
    "$(daemon_log | grep -m 1 'refused a subscriber')"
else
  fail refuse-not-allowed "root: exit $sub_rc, $sub_meshes meshes: $(first_line "$sub_out");" \
    "refusal logged: $(refusal_logged && echo yes || echo no)"
fi

# --- journald-restart, journald-stop: the daemon outlives its journal -----------------------
# The daemon's standard error is a stream to journald, and it logs all the time: a
# subscriber's arrival and departure at once, the counter line every 10 s (stats.log_interval_s)
# from its main loop. Whatever becomes of that stream, the daemon must go on serving: the same
# MainPID, no restart, subscribers still get meshes.
#
# watch_daemon SECONDS: watches the daemon for SECONDS (every 0.2 s); sets died to how it
# ended if its MainPID changed meanwhile ("" if not).
watch_daemon() {
  local deadline=$((SECONDS + $1)) main
  died=""
  while [ "$SECONDS" -lt "$deadline" ]; do
    main="$(prop MainPID)"
    if [ "$main" != "$pid" ]; then
      died="MainPID $pid -> $main: $(systemctl show -p Result -p ExecMainCode -p ExecMainStatus \
        "$unit" | paste -sd ' ')"
      return
    fi
    sleep 0.2
  done
}
# judge_outlived NAME WHAT...: the verdict of a journald check, from pid, restarts and died.
judge_outlived() {
  local name=$1
  shift
  local what="$*"
  subscribe tm-member 2
  if [ -z "$died" ] && running && [ "$(prop MainPID)" = "$pid" ] &&
    [ "$(prop NRestarts)" = "$restarts" ] && [ "$sub_rc" = 0 ] && [ "$sub_meshes" -ge 2 ]; then
    pass "$name" "$what: MainPID $pid and NRestarts=$restarts unchanged 12 s later," \
      "a subscriber then got $sub_meshes meshes"
  else
    fail "$name" "$what: the daemon ${died:+died ($died), }now $(state);" \
      "a subscriber then: exit $sub_rc, $sub_meshes meshes"
  fi
}

# journald-restart: journald hands the streams of its clients to systemd's file descriptor
# store (FileDescriptorStoreMax= in systemd-journald.service) and takes them back when it
# restarts, so the daemon's standard error stays connected, to the new journald.
pid="$(prop MainPID)" restarts="$(prop NRestarts)"
if systemctl restart systemd-journald; then
  restarted_at="$(date '+%Y-%m-%d %H:%M:%S')"
  subscribe tm-member 2
  watch_daemon 12
  judge_outlived journald-restart "journald restarted," \
    "$(daemon_log --since="$restarted_at" | wc -l) daemon lines reached the new journald"
else
  fail journald-restart "systemctl restart systemd-journald failed"
fi
running || { systemctl reset-failed "$unit"; timeout 60 systemctl start "$unit"; }

# journald-stop: a stop (not a restart) of journald and its sockets empties that store, so the
# daemon's standard error really closes: every later log line meets a broken pipe, which must
# cost the daemon its log lines, not its life. journald is started again after 12 s.
journald_units=(systemd-journald.socket systemd-journald-dev-log.socket
  systemd-journald-audit.socket systemd-journald.service)
pid="$(prop MainPID)" restarts="$(prop NRestarts)"
if systemctl stop "${journald_units[@]}"; then
  stored="$(systemctl show -p NFileDescriptorStore --value systemd-journald)"
  subscribe tm-member 2
  watch_daemon 12
  systemctl start "${journald_units[@]}"
  judge_outlived journald-stop "journald stopped for 12 s (its file descriptor store" \
    "released: $stored streams kept), a subscriber came and went meanwhile"
else
  fail journald-stop "systemctl stop ${journald_units[*]} failed"
  systemctl start "${journald_units[@]}"
fi
# Whatever happened, the next check wants a running daemon.
running || { systemctl reset-failed "$unit"; timeout 60 systemctl start "$unit"; }

# --- sigkill-restart: a crash is restarted (Restart=on-failure, RestartSec=5s) --------------
pid="$(prop MainPID)" restarts="$(prop NRestarts)"
killed="$(now)"
systemctl kill --signal=SIGKILL --kill-who=main "$unit"
restarted() { running && [ "$(prop MainPID)" != "$pid" ] && [ "$(prop NRestarts)" -gt "$restarts" ]; }
if wait_until 40 restarted; then
  took="$(since "$killed")"
  subscribe tm-member 1
  if [ "$sub_meshes" -ge 1 ]; then
    pass sigkill-restart "running again $took s after SIGKILL (RestartSec=5s):" \
      "NRestarts $restarts -> $(prop NRestarts), MainPID $pid -> $(prop MainPID); it serves meshes"
  else
    fail sigkill-restart "restarted, but a subscriber got no mesh: $(first_line "$sub_out")"
  fi
else
  fail sigkill-restart "not running again 40 s after SIGKILL: $(state)"
fi

# --- sigterm-stop: a clean stop is a success, and not restarted -----------------------------
restarts="$(prop NRestarts)"
started="$(now)"
if timeout 30 systemctl stop "$unit"; then
  took="$(since "$started")"
  # A stop must not be followed by a restart (Restart=on-failure).
  sleep 1
  exit_status="$(prop ExecMainStatus)" result="$(prop Result)" active="$(prop ActiveState)"
  if [ "$result" = success ] && [ "$active" = inactive ] && [ "$exit_status" = 0 ] &&
    [ ! -e "$socket" ]; then
    pass sigterm-stop "stopped in $took s: Result=$result ActiveState=$active" \
      "ExecMainStatus=$exit_status, /run/tacmesh removed; last line: $(journalctl --no-pager -o cat \
      -u "$unit" -t tacmesh -n 1)"
  else
    fail sigterm-stop "after $took s: Result=$result ActiveState=$active ExecMainStatus=$exit_status" \
      "NRestarts $restarts -> $(prop NRestarts); socket left: $([ -e "$socket" ] && echo yes || echo no)"
  fi
else
  fail sigterm-stop "systemctl stop did not return within 30 s: $(state)"
fi

# --- watchdog: a stalled pipeline is killed and restarted -----------------------------------
# The drop-in (stall.conf) runs the camera of scenes/stall.toml, which hangs 1 s after every
# start, with WatchdogSec=3s and RestartSec=1s. Wanted: two watchdog kills, each followed by a
# restart, within 60 s (each cycle: 1 s + 5 s until the daemon calls itself stuck + at most 3 s
# WatchdogSec + 1 s RestartSec + the start).
mkdir -p "$(dirname "$stall_dropin")"
cp /usr/lib/tacmesh-live/stall.conf "$stall_dropin"
systemctl daemon-reload
systemctl reset-failed "$unit" 2>/dev/null
started="$(now)"
if timeout 60 systemctl start "$unit"; then
  # A start by hand sets NRestarts back to 0; counted from what it is now all the same.
  restarts="$(prop NRestarts)" first_kill=""
  restarts_at_least() { [ "$(prop NRestarts)" -ge "$((restarts + $1))" ]; }
  if wait_until 60 restarts_at_least 1; then
    first_kill="$(since "$started")"
  fi
  if [ -n "$first_kill" ] && wait_until 60 restarts_at_least 2; then
    second_kill="$(since "$started")"
    timeouts="$(journalctl --no-pager -o cat -u "$unit" --since=-90s | grep -c 'Watchdog timeout')"
    watchdog_results="$(journalctl --no-pager -o cat -u "$unit" --since=-90s |
      grep -c "Failed with result 'watchdog'")"
    stuck="$(journalctl --no-pager -o cat -u "$unit" -t tacmesh --since=-90s |
      grep -m 1 'the pipeline is stuck')"
    if [ "$timeouts" -ge 2 ] && [ "$watchdog_results" -ge 2 ]; then
      pass watchdog "NRestarts $restarts -> $(prop NRestarts): restarted $first_kill s and" \
        "$second_kill s after the start (WatchdogSec=3s, RestartSec=1s);" \
        "$timeouts x 'Watchdog timeout', $watchdog_results x Result=watchdog; the daemon: $stuck"
    else
      fail watchdog "restarted (NRestarts=$(prop NRestarts)) but not by the watchdog:" \
        "$timeouts 'Watchdog timeout' lines, $watchdog_results watchdog results"
    fi
  else
    fail watchdog "NRestarts=$(prop NRestarts) after $(since "$started") s; first restart:" \
      "${first_kill:-none}; $(state)"
  fi
else
  fail watchdog "systemctl start failed: $(state)"
fi
timeout 30 systemctl stop "$unit"
rm -f "$stall_dropin"
systemctl daemon-reload

# --- the end -------------------------------------------------------------------------------
journalctl --no-pager -b -o short-monotonic -u "$unit" -u systemd-journald.service >"$out/journal.txt"
mv "$partial" "$out/results"
echo "tacmesh live checks: $(grep -c '^PASS' "$out/results") passed," \
  "$(grep -c '^FAIL' "$out/results") failed"
