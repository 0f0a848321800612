#!/usr/bin/env bash
# package_test.sh — the Debian package end to end (packaging/CMakeLists.txt, docs/systemd.md).
# Builds it (`--target package`), checks its file list, control fields and maintainer
# scripts, runs lintian (errors and warnings fail unless the package overrides them), then
# installs it with apt into a throwaway Debian root, a debootstrap minbase chroot of this
# machine's release, so that dpkg runs the maintainer scripts as on a real machine:
#   1. without systemd: adduser and install -d make the user and the state directory;
#      the installed mocapd --check-config accepts the installed conffile and refuses a
#      broken copy; purge removes the files, the empty state directory, the conffile;
#   2. with systemd: systemd-sysusers and the shipped snippet make the user again, and
#      systemd-analyze verify checks the installed unit inside that root (below).
# No file system is mounted in the chroot: apt, dpkg, the maintainer scripts, mocapd
# --check-config and systemd-analyze verify all work without /proc. The chroot is unpacked
# from a tarball cached in BUILD/packaging/chroot/ (debootstrap makes it on the first run and
# again when it is a week old) and removed at exit, failure included; the .debs apt
# downloads into it are kept there too, so a rerun needs no network.
# Needs root (chroot, file ownerships); as another user it says so and exits 77 (skipped).
#
#   package_test.sh BUILD_DIR
set -euo pipefail
build="$(cd "$1" && pwd)"
started=$SECONDS
step() { printf '[package_test %3ds] %s\n' $((SECONDS - started)) "$*"; }
fail() {
    echo "package_test: FAIL: $*" >&2
    exit 1
}

if [[ $(id -u) -ne 0 ]]; then
    echo "package_test: needs root (chroot, dpkg): skipped"
    exit 77
fi

work="$(mktemp -d "${TMPDIR:-/tmp}/mocapd-package.XXXXXX")"
cleanup() {
    # debootstrap mounts /proc in the root it makes; a failure may leave it mounted.
    findmnt -rn -o TARGET | grep "^$work/" | sort -r | xargs -r umount -l || true
    rm -rf --one-file-system "$work"
}
trap cleanup EXIT

prefix="$(sed -n 's/^CMAKE_INSTALL_PREFIX:PATH=//p' "$build/CMakeCache.txt")"
[[ $prefix == /usr ]] || fail "$build installs into $prefix; the package needs /usr: reconfigure with -DCMAKE_INSTALL_PREFIX=/usr"
arch="$(dpkg --print-architecture)"
step "cmake --build --target package"
rm -f "$build"/mocapd_*.deb
cmake --build "$build" --target package >"$work/cpack.log" 2>&1 || {
    cat "$work/cpack.log"
    fail "the package target failed"
}
debs=("$build"/mocapd_*_"$arch".deb)
[[ ${#debs[@]} -eq 1 && -f ${debs[0]} ]] || fail "not one build/mocapd_<version>_$arch.deb: ${debs[*]}"
deb="${debs[0]}"
step "$(basename "$deb"): $(stat -c %s "$deb") bytes"

# --- File list: everything outside the documentation, exactly; documentation by kind.
dpkg-deb -c "$deb" >"$work/contents"
awk '$2 != "root/root" { print "not root/root: " $0 }' "$work/contents" | grep . && fail "file owners"
awk '{ print $6 }' "$work/contents" | sed 's#^\./#/#' | grep -v '/$' | LC_ALL=C sort >"$work/files"
grep -v '^/usr/share/doc/mocapd/docs/' "$work/files" >"$work/files.main" || true
cat >"$work/files.expected" <<'EOF'
/etc/mocapd/mocapd.toml
/usr/bin/mocap-client
/usr/bin/mocap-filter
/usr/bin/mocap-sim
/usr/bin/mocapd
/usr/lib/systemd/system/mocapd.service
/usr/lib/sysusers.d/mocapd.conf
/usr/lib/tmpfiles.d/mocapd.conf
/usr/share/doc/mocapd/README.md
/usr/share/doc/mocapd/changelog.Debian.gz
/usr/share/doc/mocapd/copyright
/usr/share/lintian/overrides/mocapd
/usr/share/man/man1/mocap-client.1.gz
/usr/share/man/man1/mocap-filter.1.gz
/usr/share/man/man1/mocap-sim.1.gz
/usr/share/man/man1/mocapd.1.gz
EOF
diff -u "$work/files.expected" "$work/files.main" || fail "file list (- expected, + packaged)"
grep -q '^/usr/share/doc/mocapd/docs/systemd\.md$' "$work/files" || fail "docs/systemd.md is not packaged"
grep '^/usr/share/doc/mocapd/docs/' "$work/files" | grep -vE '\.(md|png)$' && fail "documentation of another kind"

# --- Control: computed library dependencies, the conffile, the maintainer scripts.
depends="$(dpkg-deb -f "$deb" Depends)"
echo "Depends: $depends"
for dep in libc6 libstdc++6 libspdlog adduser procps; do
    [[ "$depends" == *"$dep"* ]] || fail "Depends lacks $dep"
done
dpkg-deb -e "$deb" "$work/control"
[[ "$(cat "$work/control/conffiles")" == /etc/mocapd/mocapd.toml ]] || fail "conffiles: $(cat "$work/control/conffiles")"
for script in postinst prerm postrm; do
    [[ -x "$work/control/$script" ]] || fail "no executable $script"
done

# --- lintian: overrides ship in the package (packaging/debian/lintian-overrides).
step "lintian"
lintian --fail-on error,warning "$deb" || fail "lintian reports errors or warnings"

# --- The throwaway root.
codename="$(. /etc/os-release && echo "$VERSION_CODENAME")"
cache="$build/packaging/chroot"
tarball="$cache/debian-$codename-minbase.tar"
mkdir -p "$cache/archives"
if [[ ! -f $tarball || -n "$(find "$tarball" -mtime +6)" ]]; then
    mirror="${MOCAP_DEBIAN_MIRROR:-http://deb.debian.org/debian}"
    step "debootstrap --variant=minbase $codename $mirror (cached as $tarball)"
    debootstrap --variant=minbase "$codename" "$work/bootstrap" "$mirror" >"$work/debootstrap.log" 2>&1 || {
        tail -n 30 "$work/debootstrap.log"
        fail "debootstrap"
    }
    rm -f "$work/bootstrap"/var/cache/apt/archives/*.deb
    tar -C "$work/bootstrap" -cf "$tarball.part" . && mv "$tarball.part" "$tarball"
    rm -rf --one-file-system "$work/bootstrap"
fi
root="$work/root"
mkdir "$root"
tar -C "$root" -xf "$tarball"
cp "$deb" "$root/tmp/"
in_root() { chroot "$root" env -i PATH=/usr/sbin:/usr/bin:/sbin:/bin DEBIAN_FRONTEND=noninteractive "$@"; }
apt_in_root() {
    cp -n "$cache"/archives/*.deb "$root/var/cache/apt/archives/" 2>/dev/null || true
    in_root apt-get install -y -q -o Dpkg::Use-Pty=0 --no-install-recommends "$@" 2>&1 | tee "$work/apt.log" ||
        fail "apt-get install $*"
    cp -n "$root"/var/cache/apt/archives/*.deb "$cache/archives/" 2>/dev/null || true
}
# The user and the state directory as the unit expects them (systemd/mocapd.sysusers.conf,
# systemd/mocapd.tmpfiles.conf).
check_user() {
    local entry
    entry="$(in_root getent passwd mocapd)" || fail "no user mocapd"
    [[ "$(cut -d: -f6,7 <<<"$entry")" == /var/lib/mocapd:/usr/sbin/nologin ]] || fail "user mocapd: $entry"
    [[ "$(in_root stat -c '%U:%G %a' /var/lib/mocapd)" == "mocapd:mocapd 750" ]] ||
        fail "/var/lib/mocapd: $(in_root stat -c '%U:%G %a' /var/lib/mocapd)"
}

step "1: apt install ./$(basename "$deb") without systemd"
apt_in_root "/tmp/$(basename "$deb")"
grep -q "^Creating user 'mocapd'" "$work/apt.log" && fail "systemd-sysusers ran in a root without systemd"
check_user
in_root dpkg-query -W -f='${Conffiles}\n' mocapd | grep -q '^ /etc/mocapd/mocapd.toml ' || fail "conffile not registered"
in_root mocapd --check-config /etc/mocapd/mocapd.toml || fail "installed mocapd refuses the installed config"
sed 's/^level = "info"$/level = "loud"/' "$root/etc/mocapd/mocapd.toml" >"$root/tmp/broken.toml"
if in_root mocapd --check-config /tmp/broken.toml; then fail "mocapd --check-config accepts level = \"loud\""; fi

step "1: apt purge"
in_root apt-get purge -y -q -o Dpkg::Use-Pty=0 mocapd || fail "apt-get purge"
for gone in /usr/bin/mocapd /etc/mocapd /var/lib/mocapd /usr/lib/systemd/system/mocapd.service; do
    [[ ! -e "$root$gone" ]] || fail "$gone is left after purge"
done

step "2: apt install systemd, then ./$(basename "$deb") (systemd-sysusers makes the user)"
in_root userdel mocapd
apt_in_root systemd
apt_in_root "/tmp/$(basename "$deb")"
grep -q "^Creating user 'mocapd' (mocapd motion capture daemon)" "$work/apt.log" ||
    fail "the postinst did not run systemd-sysusers on the shipped snippet"
check_user
# The chroot's own systemd-analyze (this release's) on the installed unit: it loads the unit
# and what it pulls in (sysinit.target ...) from the chroot and checks that ExecStart= and
# ExecReload= name executables there, so a unit whose ExecStart does not follow the
# installed path fails. --man=no: the Documentation= man page is checked by the file list
# and lintian (man-db is not in a minbase root).
step "2: systemd-analyze verify"
in_root systemd-analyze verify --man=no mocapd.service || fail "systemd-analyze verify"
grep -q '^ExecStart=/usr/bin/mocapd --config /etc/mocapd/mocapd.toml$' "$root/usr/lib/systemd/system/mocapd.service" ||
    fail "ExecStart: $(grep '^ExecStart=' "$root/usr/lib/systemd/system/mocapd.service")"
step "passed"
