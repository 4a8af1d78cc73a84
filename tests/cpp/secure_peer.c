/* An independent secure DDS peer: Eclipse Cyclone DDS (Debian's libddsc with its DDS
 * Security plugins, configured through CYCLONEDDS_URI by the test) reading /rpkm/tcp_estimate
 * (DDS topic rt/rpkm/tcp_estimate) as a ROS 2 subscriber would.
 *
 *   secure_peer DOMAIN COUNT TIMEOUT_S
 *
 * Prints one line per sample, `seq X Y` (x, y in m, %.17g: exact), then `DONE n`; exit 0
 * when COUNT samples arrived, 2 on timeout, 3 when the participant cannot be created (the
 * security configuration refused: Cyclone's own message goes to stderr). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dds/dds.h"
#include "tcp_estimate.h"

int main(int argc, char **argv)
{
  if (argc != 4) {
    fprintf(stderr, "usage: secure_peer DOMAIN COUNT TIMEOUT_S\n");
    return 64;
  }
  dds_domainid_t domain = (dds_domainid_t)atoi(argv[1]);
  long count = atol(argv[2]);
  double timeout_s = atof(argv[3]);

  dds_entity_t participant = dds_create_participant(domain, NULL, NULL);
  if (participant < 0) {
    fprintf(stderr, "secure_peer: participant: %s\n", dds_strretcode(-participant));
    return 3;
  }
  dds_entity_t topic = dds_create_topic(participant, &rpkm_msgs_msg_dds__TcpEstimate__desc,
                                        "rt/rpkm/tcp_estimate", NULL, NULL);
  if (topic < 0) {
    fprintf(stderr, "secure_peer: topic: %s\n", dds_strretcode(-topic));
    return 3;
  }
  dds_qos_t *qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, 4096);
  dds_entity_t reader = dds_create_reader(participant, topic, qos, NULL);
  dds_delete_qos(qos);
  if (reader < 0) {
    fprintf(stderr, "secure_peer: reader: %s\n", dds_strretcode(-reader));
    return 3;
  }
  fprintf(stderr, "secure_peer: reading rt/rpkm/tcp_estimate on domain %d\n", (int)domain);
  fflush(stderr);

  dds_time_t deadline = dds_time() + (dds_duration_t)(timeout_s * 1e9);
  long seen = 0;
  void *samples[64];
  dds_sample_info_t infos[64];
  for (int i = 0; i < 64; i++) samples[i] = NULL;
  while (seen < count && dds_time() < deadline) {
    int n = dds_take(reader, samples, infos, 64, 64);
    if (n < 0) {
      fprintf(stderr, "secure_peer: take: %s\n", dds_strretcode(-n));
      return 1;
    }
    for (int i = 0; i < n; i++) {
      if (!infos[i].valid_data) continue;
      const rpkm_msgs_msg_dds__TcpEstimate_ *e = samples[i];
      printf("%llu %.17g %.17g\n", (unsigned long long)e->seq, e->x, e->y);
      seen++;
    }
    if (n > 0) dds_return_loan(reader, samples, n);
    fflush(stdout);
    if (n == 0) dds_sleepfor(DDS_MSECS(5));
  }
  printf("DONE %ld\n", seen);
  fflush(stdout);
  dds_delete(participant);
  return seen >= count ? 0 : 2;
}
