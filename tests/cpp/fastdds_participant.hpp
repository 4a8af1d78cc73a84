// The Fast DDS participant of the test peers (fastdds_peer.cpp, fastdds_rpc_peer.cpp):
// loopback discovery as the Cyclone peers (127.0.0.1 as an initial peer), and DDS Security
// from an SROS2 enclave when one is given (cert.pem, key.pem, identity_ca.cert.pem,
// permissions_ca.cert.pem, governance.p7s, permissions.p7s), the properties rmw_fastrtps
// sets from it. With ROS_LOCALHOST_ONLY=1 in the environment, the transports rmw_fastrtps
// (Humble) makes then: UDPv4 on 127.0.0.1 only, no builtin transports.
#pragma once

#include <cstdlib>
#include <memory>
#include <string>

#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>

#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastrtps/utils/IPLocator.h>

inline eprosima::fastdds::dds::DomainParticipantQos participant_qos(const char *name,
                                                                    const char *enclave) {
  eprosima::fastdds::dds::DomainParticipantQos qos = eprosima::fastdds::dds::PARTICIPANT_QOS_DEFAULT;
  qos.name(name);
  eprosima::fastrtps::rtps::Locator_t peer;
  eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
  qos.wire_protocol().builtin.initialPeersList.push_back(peer);
  const char *localhost = std::getenv("ROS_LOCALHOST_ONLY");
  if (localhost != nullptr && std::string(localhost) == "1") {
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.emplace_back("127.0.0.1");
    qos.transport().use_builtin_transports = false;
    qos.transport().user_transports.push_back(udp);
  }
  if (enclave != nullptr) {
    std::string dir = std::string("file://") + enclave + "/";
    auto &p = qos.properties().properties();
    p.emplace_back("dds.sec.auth.plugin", "builtin.PKI-DH");
    p.emplace_back("dds.sec.auth.builtin.PKI-DH.identity_ca", dir + "identity_ca.cert.pem");
    p.emplace_back("dds.sec.auth.builtin.PKI-DH.identity_certificate", dir + "cert.pem");
    p.emplace_back("dds.sec.auth.builtin.PKI-DH.private_key", dir + "key.pem");
    p.emplace_back("dds.sec.access.plugin", "builtin.Access-Permissions");
    p.emplace_back("dds.sec.access.builtin.Access-Permissions.permissions_ca",
                   dir + "permissions_ca.cert.pem");
    p.emplace_back("dds.sec.access.builtin.Access-Permissions.governance",
                   dir + "governance.p7s");
    p.emplace_back("dds.sec.access.builtin.Access-Permissions.permissions",
                   dir + "permissions.p7s");
    p.emplace_back("dds.sec.crypto.plugin", "builtin.AES-GCM-GMAC");
  }
  return qos;
}
