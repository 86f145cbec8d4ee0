#!/usr/bin/env bash
# mtcluster across separate network stacks on one machine (optional): three network
# namespaces joined by veth pairs on a bridge act as three hosts; mpirun starts the remote
# daemons through an "rsh agent" that enters the host's namespace (with its own hostname, so Open
# MPI sees three nodes and must use TCP between them: --mca btl tcp,self). Compares the file with
# mtbuild's. Needs root (ip netns). Changes nothing outside the namespaces it creates and removes.
#   bench/cluster_netns.sh [BUILD_DIR] [TRIANGLES]   (defaults: build, 100k)
set -euo pipefail
BUILD=${1:-build}
TRI=${2:-100k}
BIN=$(cd "$BUILD/bin" && pwd)
TMP=$(mktemp -d)
NS=(mtcl0 mtcl1 mtcl2)
cleanup() {
  for ns in "${NS[@]}"; do ip netns del "$ns" 2>/dev/null || true; done
  rm -rf "$TMP"
}
trap cleanup EXIT
for ns in "${NS[@]}"; do ip netns add "$ns"; ip -n "$ns" link set lo up; done
# mtcl0 holds the bridge (the "switch") and is host 10.77.0.1; the others hang on it by veth.
ip -n mtcl0 link add br0 type bridge
ip -n mtcl0 addr add 10.77.0.1/24 dev br0
ip -n mtcl0 link set br0 up
for i in 1 2; do
  ip link add "mtclv$i" type veth peer name eth0 netns "mtcl$i"
  ip link set "mtclv$i" netns mtcl0
  ip -n mtcl0 link set "mtclv$i" master br0 up
  ip -n "mtcl$i" addr add "10.77.0.$((i + 1))/24" dev eth0
  ip -n "mtcl$i" link set eth0 up
done
# The rsh agent: `agent HOST COMMAND...` runs COMMAND in HOST's namespace with hostname = HOST's.
cat > "$TMP/agent.sh" <<'AGENT'
#!/usr/bin/env bash
host=$1; shift
case $host in 10.77.0.2) ns=mtcl1 ;; 10.77.0.3) ns=mtcl2 ;; *) echo "agent: unknown host $host" >&2; exit 1 ;; esac
exec ip netns exec "$ns" unshare --uts sh -c "hostname $ns; $*"
AGENT
chmod +x "$TMP/agent.sh"
printf '10.77.0.1 slots=1\n10.77.0.2 slots=1\n10.77.0.3 slots=1\n' > "$TMP/hosts"
vethbytes() { ip -n mtcl0 -s link show "$1" | awk '/RX:/{getline; rx=$1} /TX:/{getline; tx=$1} END{print rx + tx}'; }

"$BIN/mtgen" -o "$TMP/scan.ply" --triangles "$TRI" --holes 10 --seed 51 > /dev/null 2>&1
"$BIN/mtbuild" "$TMP/scan.ply" -o "$TMP/ref.mt" -q > /dev/null 2>&1
# mpirun itself runs in mtcl0 under its own hostname, so 10.77.0.1 is its local node.
ip netns exec mtcl0 unshare --uts sh -c "hostname mtcl0; mpirun --allow-run-as-root -np 3 --hostfile $TMP/hosts \
  --mca plm_rsh_agent $TMP/agent.sh --mca plm_rsh_no_tree_spawn 1 --mca btl tcp,self \
  --mca btl_tcp_if_include 10.77.0.0/24 --mca oob_tcp_if_include 10.77.0.0/24 \
  --map-by node -x PATH sh -c 'echo rank \$OMPI_COMM_WORLD_RANK on \$(hostname)' " 2>&1 | sort
ip netns exec mtcl0 unshare --uts sh -c "hostname mtcl0; mpirun --allow-run-as-root -np 3 --hostfile $TMP/hosts \
  --mca plm_rsh_agent $TMP/agent.sh --mca plm_rsh_no_tree_spawn 1 --mca btl tcp,self \
  --mca btl_tcp_if_include 10.77.0.0/24 --mca oob_tcp_if_include 10.77.0.0/24 \
  --map-by node $BIN/mtcluster $TMP/scan.ply -o $TMP/c.mt -q --stats-json $TMP/c.json" 2>&1 | tail -8
grep -o '"bytes_sent": [0-9]*' "$TMP/c.json" | tr '\n' ' '; echo
echo "veth traffic (both directions): host mtcl1 $(vethbytes mtclv1) bytes, host mtcl2 $(vethbytes mtclv2) bytes"
if cmp -s "$TMP/c.mt" "$TMP/ref.mt"; then echo "netns cluster: 3 hosts, file identical to mtbuild"; else echo "netns cluster: DIFFERENT or missing"; exit 1; fi
