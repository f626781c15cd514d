#!/usr/bin/env bash
# Starts lcm-spy with modalwatch's message types, so that it decodes the
# samples, estimates, fault status and heartbeat channels.
#   scripts/lcm-spy.sh                          # default URL (lcm.url default, ttl=0)
#   scripts/lcm-spy.sh --lcm-url='udpm://239.255.76.67:7667?ttl=0'
#   scripts/lcm-spy.sh --check                  # only check that Java finds every class
# Needs (Debian): liblcm-bin (lcm-spy), liblcm-java (lcm.jar), libjchart2d-java,
# a JDK (javac, to build the types jar); scripts/setup.sh installs them. The jar
# is a CMake target (lcmtypes/CMakeLists.txt), defined when javac and lcm.jar
# exist at configure time; this script builds it in BUILD_DIR (build) when missing.
# Debian's lcm-spy 1.3.1 passes -Xincgc, which Java 17 rejects unless
# -XX:+IgnoreUnrecognizedVMOptions is set; it finds the types on CLASSPATH.
set -euo pipefail
source "$(dirname "$0")/lib/daemon.sh"
build_dir="${BUILD_DIR:-$MW_ROOT/build}"
jar="$build_dir/lcmtypes/modalwatch_lcmtypes.jar"
lcm_jar=/usr/share/java/lcm.jar
jchart_jar=/usr/share/java/jchart2d.jar

missing=()
command -v java >/dev/null || missing+=("java (default-jdk-headless or openjdk-17-jdk-headless)")
command -v lcm-spy >/dev/null || missing+=("lcm-spy (liblcm-bin)")
[ -f "$lcm_jar" ] || missing+=("$lcm_jar (liblcm-java)")
[ -f "$jchart_jar" ] || missing+=("$jchart_jar (libjchart2d-java)")
if ((${#missing[@]})); then
  printf 'lcm-spy.sh: missing: %s\n' "${missing[@]}" >&2
  echo "lcm-spy.sh: scripts/setup.sh installs them" >&2
  exit 1
fi
if [ ! -f "$jar" ] && ! mw_build "$build_dir" modalwatch_lcmtypes_jar; then
  echo "lcm-spy.sh: could not build $jar (the target exists only when CMake found javac and $lcm_jar)" >&2
  exit 1
fi

export CLASSPATH="$jar${CLASSPATH:+:$CLASSPATH}"
export JAVA_TOOL_OPTIONS="-XX:+IgnoreUnrecognizedVMOptions${JAVA_TOOL_OPTIONS:+ $JAVA_TOOL_OPTIONS}"

if [ "${1:-}" = "--check" ]; then
  # Loads lcm-spy's main class and every modalwatch type with the class path
  # lcm-spy uses, and checks each type has the LCM fingerprint lcm-spy looks for.
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  cat >"$tmp/Check.java" <<'JAVA'
public class Check {
  public static void main(String[] a) throws Exception {
    Class.forName("lcm.spy.Spy");
    Class.forName("info.monitorenter.gui.chart.Chart2D");
    String[] types = {"sample_t", "sample_batch_t", "sample2_t", "sample_batch2_t", "mode_estimate_t", "estimates_t", "quantity_status_t", "mode_status_t", "fault_status_t", "heartbeat_t"};
    for (String t : types) {
      Class<?> c = Class.forName("modalwatch." + t);
      long fp = c.getField("LCM_FINGERPRINT").getLong(null);
      System.out.printf("modalwatch.%s fingerprint 0x%016x%n", t, fp);
    }
    System.out.println("OK: lcm.spy.Spy, jchart2d and " + types.length + " modalwatch types load");
  }
}
JAVA
  cp="$CLASSPATH:$lcm_jar:$jchart_jar"
  javac -nowarn -cp "$cp" -d "$tmp" "$tmp/Check.java" 2>&1 | grep -v '^Picked up JAVA_TOOL_OPTIONS' || true
  java -cp "$tmp:$cp" Check
  exit $?
fi

exec lcm-spy "$@"
