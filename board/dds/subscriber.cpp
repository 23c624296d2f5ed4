#include "subscriber.hpp"

#include <dds/ddsi/ddsi_serdata.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <ctime>
#include <thread>

#include "diagnostic_msgs.h"
#include "geometry_msgs.h"
#include "nav_msgs.h"
#include "sensor_msgs.h"
#include "geographic_msgs.h"
#include "std_msgs.h"
#include "tf2_msgs.h"
#include "trailnav/runtime/clock.hpp"
#include "trailnav_msgs.h"

namespace trailnav::dds {

namespace {
// The type name of the first writer of `topic` that discovery reports, and
// whether that writer keeps samples for late joiners (transient-local).
std::string discover_type(const Domain& domain, const std::string& topic, double timeout_s, bool& transient_local) {
  const dds_entity_t reader = dds_create_reader(domain.participant(), DDS_BUILTIN_TOPIC_DCPSPUBLICATION, nullptr, nullptr);
  if (reader < 0) return {};
  std::string type;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  while (type.empty() && std::chrono::steady_clock::now() < deadline) {
    void* samples[16] = {};
    dds_sample_info_t infos[16];
    const dds_return_t n = dds_take(reader, samples, infos, 16, 16);
    for (dds_return_t i = 0; i < n; ++i) {
      if (!infos[i].valid_data) continue;
      const auto* e = static_cast<const dds_builtintopic_endpoint_t*>(samples[i]);
      if (type.empty() && e->topic_name != nullptr && topic == e->topic_name && e->type_name != nullptr) {
        type = e->type_name;
        dds_durability_kind_t kind = DDS_DURABILITY_VOLATILE;
        transient_local = e->qos != nullptr && dds_qget_durability(e->qos, &kind) && kind != DDS_DURABILITY_VOLATILE;
      }
    }
    if (n > 0) dds_return_loan(reader, samples, n);
    if (type.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  dds_delete(reader);
  return type;
}
}  // namespace

const dds_topic_descriptor_t* known_type(const std::string& name) noexcept {
  static const dds_topic_descriptor_t* const kTypes[] = {
      &nav_msgs_msg_dds__OccupancyGrid__desc,       &nav_msgs_msg_dds__Path__desc,
      &geometry_msgs_msg_dds__PoseStamped__desc,    &geometry_msgs_msg_dds__PoseWithCovarianceStamped__desc,
      &sensor_msgs_msg_dds__NavSatFix__desc,        &diagnostic_msgs_msg_dds__DiagnosticArray__desc,
      &trailnav_msgs_msg_dds__TerrainClassMap__desc, &tf2_msgs_msg_dds__TFMessage__desc,
      &nav_msgs_msg_dds__Odometry__desc,            &trailnav_msgs_msg_dds__NavigationStatus__desc,
      &geographic_msgs_msg_dds__GeoPoseStamped__desc, &std_msgs_msg_dds__Empty__desc,
      &sensor_msgs_msg_dds__PointCloud2__desc,      &trailnav_msgs_msg_dds__PlaceMatch__desc,
      &trailnav_msgs_msg_dds__StationFix__desc,     &sensor_msgs_msg_dds__LaserScan__desc};
  for (const dds_topic_descriptor_t* t : kTypes) {
    if (name == t->m_typename) return t;
  }
  return nullptr;
}

Subscriber::Created Subscriber::create(const Domain& domain, const std::string& topic_name,
                                       const dds_topic_descriptor_t* type, double discover_timeout_s,
                                       bool transient_local, int depth) {
  Created result;
  std::unique_ptr<Subscriber> s(new Subscriber());
  s->topic_ = ros_topic(topic_name);
  if (type == nullptr) {
    const std::string name = discover_type(domain, s->topic_, discover_timeout_s, transient_local);
    if (name.empty()) {
      result.error = "no writer of " + s->topic_ + " found within " + std::to_string(static_cast<int>(discover_timeout_s)) +
                     " s (is trailnavd running, on the same DDS domain and Cyclone configuration?)";
      return result;
    }
    type = known_type(name);
    if (type == nullptr) {
      result.error = s->topic_ + " carries " + name + ", a type trailnav does not know";
      return result;
    }
  }
  s->type_ = type;
  s->topic_entity_ = dds_create_topic(domain.participant(), type, s->topic_.c_str(), nullptr, nullptr);
  if (s->topic_entity_ < 0) {
    result.error = "topic " + s->topic_ + ": " + dds_strretcode(s->topic_entity_);
    s->topic_entity_ = 0;
    return result;
  }
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, std::max(depth, 1));
  // Paths and tf_static are offered transient local by their writers (tf2's
  // convention for tf_static): a late subscriber then still gets them.
  if (transient_local || type == &nav_msgs_msg_dds__Path__desc || s->topic_ == "rt/tf_static") {
    dds_qset_durability(q, DDS_DURABILITY_TRANSIENT_LOCAL);
  }
  s->reader_ = dds_create_reader(domain.participant(), s->topic_entity_, q, nullptr);
  dds_delete_qos(q);
  if (s->reader_ < 0) {
    result.error = "reader on " + s->topic_ + ": " + dds_strretcode(s->reader_);
    s->reader_ = 0;
    return result;
  }
  s->waitset_ = dds_create_waitset(domain.participant());
  s->condition_ = dds_create_readcondition(s->reader_, DDS_ANY_STATE);
  dds_waitset_attach(s->waitset_, s->condition_, s->reader_);
  s->sample_ = dds_alloc(type->m_size);
  result.subscriber = std::move(s);
  return result;
}

Subscriber::~Subscriber() {
  if (sample_ != nullptr) dds_sample_free(sample_, type_, DDS_FREE_ALL);
  if (waitset_ > 0) dds_delete(waitset_);
  if (condition_ > 0) dds_delete(condition_);
  if (reader_ > 0) dds_delete(reader_);
  if (topic_entity_ > 0) dds_delete(topic_entity_);
}

int Subscriber::take(double timeout_s, const std::function<void(const ReceivedSample&)>& fn) {
  dds_attach_t triggered[1];
  dds_waitset_wait(waitset_, triggered, 1, static_cast<dds_duration_t>(timeout_s * 1e9));
  int taken = 0;
  for (;;) {
    ddsi_serdata* sd = nullptr;
    dds_sample_info_t info;
    if (dds_takecdr(reader_, &sd, 1, &info, DDS_ANY_STATE) != 1) break;
    const std::int64_t now = wall_clock_ns();
    if (info.valid_data) {
      ReceivedSample r;
      r.type = type_;
      r.wire_bytes = ddsi_serdata_size(sd);
      r.source_ns = info.source_timestamp;
      r.receive_ns = now;
      dds_sample_free(sample_, type_, DDS_FREE_CONTENTS);
      std::memset(sample_, 0, type_->m_size);
      if (ddsi_serdata_to_sample(sd, sample_, nullptr, nullptr)) {
        r.sample = sample_;
        fn(r);
        ++taken;
      }
    }
    ddsi_serdata_unref(sd);
  }
  return taken;
}

}  // namespace trailnav::dds
