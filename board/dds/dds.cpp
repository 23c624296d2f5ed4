#include "dds.hpp"

#include "dds_loopback.hpp"  // generated from cyclone-loopback.xml

#include <fstream>
#include <sstream>

#include "trailnav/runtime/host_clock.hpp"

namespace trailnav::dds {

const char* loopback_config() noexcept { return kLoopbackConfig; }

Domain::Created Domain::create(std::uint32_t domain_id, const std::string& config_xml) {
  Created result;
  std::unique_ptr<Domain> d(new Domain());
  d->id_ = domain_id;
  const dds_entity_t domain = dds_create_domain(domain_id, config_xml.c_str());
  if (domain < 0 && domain != DDS_RETCODE_PRECONDITION_NOT_MET) {
    result.error = "DDS domain " + std::to_string(domain_id) + ": Cyclone rejected the configuration (" +
                   dds_strretcode(domain) + "); its log on stderr says why";
    return result;
  }
  d->domain_ = domain > 0 ? domain : 0;
  d->participant_ = dds_create_participant(domain_id, nullptr, nullptr);
  if (d->participant_ < 0) {
    result.error = "DDS domain " + std::to_string(domain_id) + ": cannot create a participant (" +
                   dds_strretcode(d->participant_) + ")";
    d->participant_ = 0;
    return result;
  }
  result.domain = std::move(d);
  return result;
}

Domain::~Domain() {
  if (participant_ > 0) dds_delete(participant_);
  if (domain_ > 0) dds_delete(domain_);
}

ConfigText read_cyclone_config(const std::string& path) {
  ConfigText out;
  std::ifstream in(path);
  if (!in) {
    out.error = "cannot read the Cyclone DDS configuration " + path;
    return out;
  }
  std::ostringstream text;
  text << in.rdbuf();
  out.xml = text.str();
  if (out.xml.find("<CycloneDDS") == std::string::npos) {
    out.error = path + ": not a Cyclone DDS configuration (no <CycloneDDS> element)";
    out.xml.clear();
  }
  return out;
}

std::string ros_topic(const std::string& name) { return "rt/" + name; }

Writer::Created Writer::create(const Domain& domain, const dds_topic_descriptor_t& type, const std::string& topic_name,
                               const EndpointQos& qos) {
  Created result;
  std::unique_ptr<Writer> w(new Writer());
  w->topic_ = ros_topic(topic_name);
  w->topic_entity_ = dds_create_topic(domain.participant(), &type, w->topic_.c_str(), nullptr, nullptr);
  if (w->topic_entity_ < 0) {
    result.error = "topic " + w->topic_ + ": " + dds_strretcode(w->topic_entity_);
    w->topic_entity_ = 0;
    return result;
  }
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, qos.reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, qos.depth);
  dds_qset_durability(q, qos.durability == Durability::transient_local ? DDS_DURABILITY_TRANSIENT_LOCAL
                                                                        : DDS_DURABILITY_VOLATILE);
  w->writer_ = dds_create_writer(domain.participant(), w->topic_entity_, q, nullptr);
  dds_delete_qos(q);
  if (w->writer_ < 0) {
    result.error = "writer on " + w->topic_ + ": " + dds_strretcode(w->writer_);
    w->writer_ = 0;
    return result;
  }
  result.writer = std::move(w);
  return result;
}

Writer::~Writer() {
  if (writer_ > 0) dds_delete(writer_);
  if (topic_entity_ > 0) dds_delete(topic_entity_);
}

bool Writer::write(const void* sample, std::int64_t source_ns) noexcept {
  // The source timestamp in host time, put on the system clock of this moment.
  const dds_return_t rc =
      source_ns > 0 ? dds_write_ts(writer_, sample, host_to_realtime(source_ns)) : dds_write(writer_, sample);
  if (rc == DDS_RETCODE_OK) {
    ++written_;
    return true;
  }
  ++failed_;
  return false;
}

SampleReader::Created SampleReader::create(const Domain& domain, const dds_topic_descriptor_t& type,
                                           const std::string& topic_name, const EndpointQos& qos) {
  Created result;
  std::unique_ptr<SampleReader> r(new SampleReader());
  r->topic_ = ros_topic(topic_name);
  r->topic_entity_ = dds_create_topic(domain.participant(), &type, r->topic_.c_str(), nullptr, nullptr);
  if (r->topic_entity_ < 0) {
    result.error = "topic " + r->topic_ + ": " + dds_strretcode(r->topic_entity_);
    r->topic_entity_ = 0;
    return result;
  }
  dds_qos_t* q = dds_create_qos();
  dds_qset_reliability(q, qos.reliable ? DDS_RELIABILITY_RELIABLE : DDS_RELIABILITY_BEST_EFFORT, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, qos.depth);
  r->reader_ = dds_create_reader(domain.participant(), r->topic_entity_, q, nullptr);
  dds_delete_qos(q);
  if (r->reader_ < 0) {
    result.error = "reader on " + r->topic_ + ": " + dds_strretcode(r->reader_);
    r->reader_ = 0;
    return result;
  }
  r->waitset_ = dds_create_waitset(domain.participant());
  dds_set_status_mask(r->reader_, DDS_DATA_AVAILABLE_STATUS);
  dds_waitset_attach(r->waitset_, r->reader_, r->reader_);
  result.reader = std::move(r);
  return result;
}

SampleReader::~SampleReader() {
  stop();
  for (dds_entity_t e : {waitset_, reader_, topic_entity_}) {
    if (e > 0) dds_delete(e);
  }
}

void SampleReader::start(void* sample, std::function<void()> on_sample) {
  if (running_.exchange(true)) return;
  sample_ = sample;
  on_sample_ = std::move(on_sample);
  thread_ = std::thread([this] { loop(); });
}

void SampleReader::stop() {
  if (!running_.exchange(false)) return;
  if (waitset_ > 0) dds_waitset_set_trigger(waitset_, true);
  if (thread_.joinable()) thread_.join();
}

void SampleReader::loop() noexcept {
  while (running_.load(std::memory_order_acquire)) {
    dds_attach_t triggered[1];
    dds_waitset_wait(waitset_, triggered, 1, DDS_MSECS(200));
    if (!running_.load(std::memory_order_acquire)) break;
    dds_sample_info_t info;
    void* one[1] = {sample_};
    while (dds_take(reader_, one, &info, 1, 1) == 1) {
      if (info.valid_data) on_sample_();
    }
  }
}

ConfigText cyclone_config_or_loopback(const std::string& path) {
  if (path.empty()) return {loopback_config(), {}};
  return read_cyclone_config(path);
}

std::string with_small_receive_buffer(const std::string& xml) {
  static constexpr const char* kBuffer = "<SocketReceiveBufferSize min=\"80kB\" max=\"80kB\"/>";
  std::string out = xml;
  if (const auto at = out.find("<Internal>"); at != std::string::npos) {
    out.insert(at + std::string("<Internal>").size(), kBuffer);
  } else if (const auto end = out.rfind("</Domain>"); end != std::string::npos) {
    out.insert(end, std::string("<Internal>") + kBuffer + "</Internal>");
  }
  return out;
}

}  // namespace trailnav::dds
